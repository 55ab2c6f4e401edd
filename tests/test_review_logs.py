"""``windseek review`` on real logs written by other software (``shared/data/logs``, see SOURCES.md there).

What an honest review of each must say:

- px4-bench-never-armed.ulg: real hardware on a bench, never armed, no land detector: not airborne,
  no wind figure (it used to report 68.9 s airborne and 22.7 m/s of wind).
- px4-vtol-short-hop.ulg: a 1.1 s hop: no settled sample, so no figure, and the reason.
- px4-sitl-quad-hover.ulg: the take-off transient (-59.8 m/s "vertical wind") is not plotted as wind.
- ardupilot-quadplane-sitl.tlog: IMU only as RAW_IMU / SCALED_IMU2 (mG, mrad/s, ~4 Hz), ArduPilot's
  WIND compared with ours, ardupilotmega messages known, and a vehicle that is not a quadrotor.
- ardupilot-dataflash-excerpt.BIN: a DataFlash log is reviewed, its values as pymavlink reads them.
- A truncated ULog: non-zero exit, a message on stderr, stdout still JSON.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.DFReader import DFReader_binary

from recording.read import RrdLog
from review.convert import ReviewResult, review
from review.detect import detect_format
from review.summary import format_summary
from windseek.cli import main as cli_main

_CANDIDATES = [Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "logs", Path("/work/shared/data/logs")]
LOGS = next((p.resolve() for p in _CANDIDATES if (p / "SOURCES.md").is_file()), None)
pytestmark = pytest.mark.skipif(LOGS is None, reason="third-party logs not found at ../shared/data/logs")


def _log(name: str) -> Path:
    assert LOGS is not None
    p = LOGS / name
    if not p.is_file():
        pytest.skip(f"{name} is not in {LOGS}")
    return p


@pytest.fixture(scope="module")
def reviews(tmp_path_factory: pytest.TempPathFactory) -> dict[str, ReviewResult]:
    d = tmp_path_factory.mktemp("real-logs")
    names = ["px4-bench-never-armed.ulg", "px4-vtol-short-hop.ulg", "px4-sitl-quad-hover.ulg",
             "ardupilot-quadplane-sitl.tlog", "ardupilot-dataflash-excerpt.BIN"]  # fmt: skip
    return {n: review(_log(n), d / f"{n}.rrd") for n in names}


def test_never_armed_bench_log_is_not_airborne(reviews: dict[str, ReviewResult]) -> None:
    r = reviews["px4-bench-never-armed.ulg"]
    s = r.summary
    assert s["airborne_s"] == 0.0 and s["airborne_segments"] == 0
    assert s["airborne_from"] == "vehicle_status (armed)"
    assert not s["wind_figure"] and "wind_mean_ned_ms" not in s
    assert s["wind_figure_reason"].startswith("not airborne"), s["wind_figure_reason"]
    assert any("never armed" in n for n in s["notes"])
    assert s["duration_s"] > 60.0 and s["autopilot"] == "PX4 (fd483321)"
    paths = RrdLog(r.out).temporal_entity_paths() + RrdLog(r.out).series()
    assert "rotors/1" in paths and not any(p.startswith(("wind/", "extra/")) for p in paths), paths
    assert any("xy_valid = 0" in n for n in s["notes"])  # a bench: no horizontal fix
    assert "wind figure: none (not airborne" in format_summary(s)


def test_short_hop_has_no_figure_and_says_why(reviews: dict[str, ReviewResult]) -> None:
    s = reviews["px4-vtol-short-hop.ulg"].summary
    assert 0.8 < s["airborne_s"] < 1.5 and s["wind_estimated"]
    assert not s["wind_figure"] and "wind_mean_ned_ms" not in s and "diff_vs_autopilot_ms" not in s
    assert "first 5 s" in s["wind_figure_reason"] and s["samples_settling"] == s["samples_total"] > 0
    assert s["autopilot"].startswith("PX4 v1.11.2 (dev)")  # ver_sw_release 17498624 = 0x010B0200
    assert "VTOL" in s["vehicle_type"] and "not a quadrotor" in s["model"]
    text = format_summary(s)
    assert "wind figure: none (no estimate sample qualifies" in text and "-21.1" not in text


def test_hover_take_off_transient_is_not_plotted_as_wind(reviews: dict[str, ReviewResult]) -> None:
    r = reviews["px4-sitl-quad-hover.ulg"]
    s = r.summary
    assert s["wind_figure"] and 0 < s["samples_scored"] < s["samples_total"]
    assert s["samples_settling"] > 0 and s["samples_near_ground"] > 0
    assert s["autopilot"].startswith("PX4 v1.15.0 (dev)")
    log = RrdLog(r.out)
    _, down = log.scalars("wind/down/estimate")
    assert len(down) == s["samples_scored"] and np.abs(down).max() < 10.0
    _, bad = log.scalars("extra/untrusted_wind_m_s/down")
    # The take-off transient (the identified model meets PX4's 1.5 kg Iris: a wind of -11 m/s, never scored).
    assert len(bad) == s["samples_total"] - s["samples_scored"] and bad.min() < -5.0
    # PX4's SITL quadrotor is not nasa-quad: the review says the model does not fit (the wind that would
    # explain its forces is a 5 m/s vertical airspeed the identification never flew), not a wind.
    fit = s["model_fit"]
    assert fit["model"] == "nasa-quad" and fit["model_fits"] is False and "never identified" in fit["model_note"]
    # ...and the figure it still shows says so, as the live estimator would publish nothing.
    line = next(x for x in format_summary(s).splitlines() if x.startswith("wind estimate"))
    assert line.startswith("wind estimate WITHHELD by the model check, shown for reference only"), line


def test_review_counts_time_from_the_log_start(reviews: dict[str, ReviewResult]) -> None:
    """The PX4 SITL hover log is stamped in UNIX time (1.71e9 s): its recording counts from the log's
    start on the live runs' timeline, so the viewer's axes read 0..31 s and the plots open on the
    flight, not "+19800d"; the VTOL hop's boot clock (logging from 19.4 s) reads from 0 too."""
    from pyulog import ULog

    from recording.style import TIMELINE

    r = reviews["px4-sitl-quad-hover.ulg"]
    log = RrdLog(r.out)
    assert TIMELINE in log.timelines()
    u = ULog(str(_log("px4-sitl-quad-hover.ulg")), ["esc_status"])
    assert u.start_timestamp * 1e-6 == pytest.approx(1710773350.346)  # UNIX time; first event at .126 s
    t, _ = log.scalars("rotors/1")
    esc_t0 = u.get_dataset("esc_status").data["timestamp"][0] * 1e-6
    assert abs(t[0] - (esc_t0 - 1710773350.0)) < 1e-3  # the log's clock minus 1710773350 s
    assert 0.0 <= t[0] < 1.0 and 30.0 < t[-1] < 32.0  # 31.1 s of log
    events = [ti for e in log.temporal_entity_paths() if e.startswith("log/") for ti, _ in log.texts(e)]
    assert min(events) >= 0.0 and max(events) < 32.0
    s = log.summary()
    assert s is not None and s.t_arm_s is not None and s.t_disarm_s is not None
    assert 14.0 < s.t_arm_s < 17.0 and 29.0 < s.t_disarm_s < 32.0  # armed 15.3 s, landed 30.5 s into the log
    assert "UNIX time: 2024-03-18 14:49:10 UTC" in s.extra["clock"]
    # Every plot and the phase lanes open on the flight: from before arming to after the disarm.
    ranges = log.blueprint_time_ranges()
    assert len(ranges) >= 4, ranges  # the wind plots and the phase lanes (no chemical, no NED plots missing)
    for t0, t1 in ranges:
        assert 0.0 <= t0 <= s.t_arm_s and s.t_disarm_s <= t1 <= 31.5 * 1.5, (t0, t1)
    # The summary's result line is the review's wind figure.
    assert s.outcome.startswith(f"wind {r.summary['wind_speed_mean_ms']:.2f} m/s from")
    hop = RrdLog(reviews["px4-vtol-short-hop.ulg"].out)
    t, _ = hop.scalars("wind/north/autopilot")
    assert 0.0 <= t[0] < 2.0 and t[-1] < 8.0  # wind_estimate from 20.3 s of the boot clock; origin 19 s


def _first(path: Path, mtype: str) -> Any:
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    try:
        return conn.recv_match(type=mtype)
    finally:
        conn.close()


def test_ardupilot_tlog_imu_units_and_wind_comparison(reviews: dict[str, ReviewResult]) -> None:
    r = reviews["ardupilot-quadplane-sitl.tlog"]
    s, fd = r.summary, r.flight
    assert s["autopilot"] == "ArduPilot v3.10.0 (dev)" and s["vehicle_type"] == "fixed wing"
    assert s["sources"]["imu"] == "RAW_IMU" and s["sources"]["autopilot_wind"] == "WIND"
    assert any("RAW_IMU (mG, mrad/s) at 3.8 Hz" in n for n in s["imu"]), s["imu"]
    assert not any("unknown message id" in n for n in s["notes"]), s["notes"]  # ardupilotmega dialect
    assert s["messages"]["WIND"] == 810 and s["messages"]["AHRS2"] == 889
    ref = _first(_log("ardupilot-quadplane-sitl.tlog"), "RAW_IMU")  # pymavlink's own reading
    k = int(np.argmin(np.abs(fd.imu.t - ref.time_usec * 1e-6)))
    assert fd.imu.v[k, 2] == pytest.approx(ref.zacc * 9.80665e-3) and fd.imu.v[k, 5] == pytest.approx(ref.zgyro * 1e-3)
    assert np.median(fd.imu.v[:, 2]) == pytest.approx(-9.8, abs=1.0)  # about 1 g up in level flight and on the ground
    # ArduPilot's WIND (SITL without wind: 0 m/s) against ours, both printed, and the difference
    assert s["autopilot_wind_mean_ned_ms"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)
    assert s["mean_diff_vs_autopilot_ned_ms"] == pytest.approx(s["wind_mean_ned_ms"], abs=1e-3)
    assert s["diff_vs_autopilot_ms"]["horizontal"] > 0.0
    text = format_summary(s)
    assert "the autopilot's estimate (WIND)" in text and "ours minus the autopilot's" in text
    assert "fixed wing, not a quadrotor" in s["model"] and s["model"] in text


def test_ardupilot_wind_message_is_decoded_as_ardupilot_sends_it(tmp_path: Path) -> None:
    """WIND: direction the wind comes from [deg], speed = 3-D length, speed_z = NED down (GCS_MAVLink_Plane.cpp)."""
    from pymavlink.dialects.v20 import ardupilotmega as ap

    from review.tlog import read_tlog

    veh = ap.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [veh.heartbeat_encode(ap.MAV_TYPE_QUADROTOR, ap.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0).pack(veh),
              veh.attitude_encode(1000, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0).pack(veh),
              veh.wind_encode(90.0, 5.0, 3.0).pack(veh)]  # fmt: skip
    path = tmp_path / "wind.tlog"
    path.write_bytes(b"".join(int(1.7e15 + i).to_bytes(8, "big") + f for i, f in enumerate(frames)))
    fd = read_tlog(path)
    assert fd.autopilot_wind.v[0] == pytest.approx([0.0, -4.0, 3.0], abs=1e-6)  # from the east: air moves west


def test_dataflash_bin_is_reviewed(reviews: dict[str, ReviewResult]) -> None:
    r = reviews["ardupilot-dataflash-excerpt.BIN"]
    s, fd = r.summary, r.flight
    assert s["kind"] == "dataflash" and s["autopilot"] == "ArduPilot ArduPlane V3.8.2-dev"
    assert s["sources"]["imu"] == "IMU" and s["sources"]["attitude"] == "ATT"
    assert s["sources"]["velocity"] == "NKF1" and s["sources"]["autopilot_wind"].startswith("NKF2")
    assert s["airborne_from"] == "STAT (isFlying)" and s["airborne_s"] == 0.0 and not s["wind_figure"]
    path = str(_log("ardupilot-dataflash-excerpt.BIN"))
    imu = DFReader_binary(path).recv_match(type="IMU")  # pymavlink's own reading (a reader per type filter)
    assert fd.imu.t[0] == pytest.approx(imu.TimeUS * 1e-6)
    assert fd.imu.v[0] == pytest.approx([imu.AccX, imu.AccY, imu.AccZ, imu.GyrX, imu.GyrY, imu.GyrZ])
    att = DFReader_binary(path).recv_match(type="ATT")
    roll, pitch, yaw = np.radians([att.Roll, att.Pitch, att.Yaw])
    q = fd.attitude.v[0]
    assert np.degrees(np.arctan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))) % 360 == \
        pytest.approx(att.Yaw, abs=1e-3)  # fmt: skip
    assert np.degrees(np.arcsin(2 * (q[0] * q[2] - q[3] * q[1]))) == pytest.approx(att.Pitch, abs=1e-3)
    assert roll < 0 and pitch > 0 and yaw >= 0
    assert any(x.startswith("ArduPlane V3.8.2") for _, x, _ in fd.texts)
    assert "world/vehicle" in RrdLog(r.out).temporal_entity_paths()


def test_truncated_ulog_fails_cleanly_with_json(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(_log("px4-bench-never-armed.ulg").read_bytes()[:10_000])
    out = tmp_path / "cut.rrd"
    assert cli_main(["review", str(cut), "-o", str(out), "--json"]) == 1
    cap = capsys.readouterr()
    s = json.loads(cap.out)  # stdout stays one JSON object: pyulog's own complaint is not on it
    assert s["usable"] is False and "nothing usable" in s["error"] and "corruption" in s["error"].lower()
    assert "error" in cap.err and "cut.ulg" in cap.err and "warning" in cap.err
    assert not out.exists()


def test_bad_inputs_get_one_line_and_json(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert cli_main(["review", str(tmp_path), "--json"]) == 2
    cap = capsys.readouterr()
    assert "is a directory" in cap.err and "is a directory" in json.loads(cap.out)["error"]
    junk = tmp_path / "junk.tlog"
    junk.write_bytes(bytes(range(256)) * 8)
    assert cli_main(["review", str(junk)]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and "not a PX4 ULog, ArduPilot DataFlash or MAVLink telemetry log" in cap.err


def test_content_detection_both_ways(tmp_path: Path) -> None:
    pairs = {"ardupilot-quadplane-sitl.tlog": ("as-ulog.ulg", "tlog"),
             "px4-vtol-short-hop.ulg": ("as-tlog.tlog", "ulog"),
             "ardupilot-dataflash-excerpt.BIN": ("as-tlog2.tlog", "dataflash")}
    for src, (dst, kind) in pairs.items():
        p = tmp_path / dst
        shutil.copyfile(_log(src), p)
        assert detect_format(p) == kind, src
    res = review(tmp_path / "as-ulog.ulg", tmp_path / "a.rrd")
    assert res.summary["kind"] == "tlog" and res.summary["sources"]["imu"] == "RAW_IMU"
    assert any("read as a tlog by its content" in n for n in res.summary["notes"])


def test_read_only_folder_is_refused_before_the_work(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The default output is next to the log: a read-only folder (like shared/data/logs) is refused up front."""
    ro = tmp_path / "ro"
    ro.mkdir()
    shutil.copyfile(_log("ardupilot-dataflash-excerpt.BIN"), ro / "x.BIN")
    ro.chmod(0o555)
    try:
        assert cli_main(["review", str(ro / "x.BIN")]) == 2
        assert "cannot write the recording there" in capsys.readouterr().err
        assert sorted(p.name for p in ro.iterdir()) == ["x.BIN"]
    finally:
        ro.chmod(0o755)


def test_decimated_imu_is_said_and_keeps_the_horizontal_figure(reviews: dict[str, ReviewResult],
                                                                tmp_path: Path) -> None:  # fmt: skip
    full = reviews["px4-sitl-quad-hover.ulg"].summary
    s = review(_log("px4-sitl-quad-hover.ulg"), tmp_path / "d.rrd", imu_rate_hz=100.0).summary
    assert not full["imu_decimated"] and s["imu_decimated"] and s["imu_rate_used_hz"] == 100.0
    assert 0.35 * full["imu_steps"] < s["imu_steps"] < 0.45 * full["imu_steps"]
    assert np.allclose(s["wind_mean_ned_ms"][:2], full["wind_mean_ned_ms"][:2], atol=0.1)
    assert "decimated from 250" in format_summary(s)


def test_damaged_logs_are_counted_never_fatal(tmp_path: Path) -> None:
    """300 random bytes changed in each log (seeded): the tlog is still reviewed with the damage counted;
    the .bin and .ulg give a usable=False result or one clear ValueError, never a crash or a hang."""
    import random

    rng = random.Random(7)
    for name in ("ardupilot-quadplane-sitl.tlog", "ardupilot-dataflash-excerpt.BIN", "px4-vtol-short-hop.ulg"):
        b = bytearray(_log(name).read_bytes()[:200_000])
        for _ in range(300):
            b[rng.randrange(len(b))] = rng.randrange(256)
        p = tmp_path / f"damaged-{name}"
        p.write_bytes(bytes(b))
        try:
            r = review(p, tmp_path / f"{name}.rrd")
        except ValueError as e:
            assert str(p) in str(e)
            continue
        if name.endswith(".tlog"):
            assert r.usable and r.summary["sources"]["imu"] == "RAW_IMU"
            assert any("bad CRC" in n or "skipped" in n for n in r.summary["notes"]), r.summary["notes"]
        else:
            assert r.usable or "nothing usable" in r.summary["error"]
