"""``windseek sitl SCENARIO --ardupilot --rrd PATH`` without ArduPilot: the JSON runner served over a real UDP
socket (servo packets from the test), its peripheral component connected over real TCP to a socket standing in
for ArduPilot's SERIAL2, which passes on what ArduPilot would: its HEARTBEAT, EKF3's WIND, its STATUSTEXT, and
the companions' WIND_COV (estimator, component 191), mission state and declaration, all pymavlink-encoded.
The recording read back holds the truth, windseek's estimate and ArduCopter's own on the same wind plots."""

from __future__ import annotations

import json
import math
import socket
import threading
from pathlib import Path

import numpy as np
import pytest
from test_ardupilot_json import FakeArduPilot

from recording.autopilot_rrd import ARDUCOPTER_LABEL
from recording.read import RrdLog
from sitl.ardupilot.launch import make_runner
from sitl.hil.launch import close_all
from windseek.cli import build_parser
from windseek.cmd_sitl import attach_autopilot_rrd
from wire.dialect import mavlink
from wire.names import ESTIMATOR_COMPONENT, MISSION_COMPONENT, declaration_messages

#: What the estimator and ArduCopter say (m/s NED; WIND as from-direction deg, horizontal speed, speed_z).
EST = (1.5, -2.0, 0.25)
VAR_H, VAR_V = 0.08, 0.04
AP_FROM_DEG, AP_SPEED, AP_Z = 90.0, 4.0, 0.5
DISARMED, CLIMB = [1000] * 4 + [0] * 12, [1950] * 4 + [0] * 12


def _what_ardupilot_passes_on(t: float) -> bytes:
    """ArduCopter's own messages and the companions' it routes to SERIAL2, as bytes on its TCP port."""
    ap, est, mission = (mavlink.MAVLink(None, 1, c) for c in (1, ESTIMATOR_COMPONENT, MISSION_COMPONENT))
    msgs = [(ap, mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                   mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 4, 3)),  # GUIDED
            (ap, mavlink.MAVLink_wind_message(AP_FROM_DEG, AP_SPEED, AP_Z)),
            (ap, mavlink.MAVLink_statustext_message(6, b"EKF3 IMU0 is using GPS")),
            (mission, mavlink.MAVLink_statustext_message(6, b"state: surge"))]  # fmt: skip
    for k in range(3):
        msgs.append((est, mavlink.MAVLink_wind_cov_message(int((t - 0.05 * k) * 1e6), *EST, VAR_H, VAR_V, 0.0, 0.0,
                                                           0.0)))  # fmt: skip
    msgs += [(mission, m) for m in declaration_messages(t, [18.0, 1.0, -2.0], 0.9)]
    return b"".join(m.pack(who) for who, m in msgs)


def _fly(tmp_path: Path) -> tuple[Path, dict, np.ndarray, np.ndarray, float]:
    """The run: 1 s on the ground, a climb, the messages once airborne, 1 s more; closed as ``run_ardupilot`` does.
    Returns the file, the runner's summary, the truth the bridge scored against (t, wind N), the messages' time."""
    serial2 = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    serial2.bind(("127.0.0.1", 0))
    serial2.listen(1)
    serial2.settimeout(10.0)
    path = tmp_path / "run.rrd"
    args = build_parser("sitl").parse_args(
        ["sitl", "open-field", "--ardupilot", "--ardupilot-port", "0", "--ardupilot-mavlink",
         f"127.0.0.1:{serial2.getsockname()[1]}", "--rrd", str(path), "--rrd-strategy", "surge-cast"])  # fmt: skip
    runner = make_runner(args, lambda s: None)
    parts = attach_autopilot_rrd(runner, args, ARDUCOPTER_LABEL)
    th = threading.Thread(target=runner.serve, kwargs={"wall_limit_s": 120.0}, daemon=True)
    th.start()
    ap = FakeArduPilot(runner.port)
    try:
        for n in range(1000):
            ap.frame(n, DISARMED)
        conn, _ = serial2.accept()  # the peripheral connected at a service of the link
        b = runner.bridge
        n = 1000
        while -b.world.position[2] < 2.0:
            ap.frame(n, CLIMB)
            n += 1
        t_msgs = b.t
        conn.sendall(_what_ardupilot_passes_on(t_msgs))
        for k in range(1000):
            ap.frame(n + k, CLIMB if k < 200 else DISARMED)
        truth = np.array(b.truth.t), np.array([w[0] for w in b.truth.w])
    finally:
        runner.stop()
        th.join(10.0)
        runner.close()
        close_all(parts, print)
        serial2.close()
    return path, runner.summary(), truth[0], truth[1], t_msgs


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> tuple[RrdLog, dict, np.ndarray, np.ndarray, float]:
    path, summary, t_truth, n_truth, t_msgs = _fly(tmp_path_factory.mktemp("ardupilot-rrd"))
    return RrdLog(path), summary, t_truth, n_truth, t_msgs


def test_truth_is_the_wind_the_bridge_scored_against(flown: tuple) -> None:
    log, _, t_truth, n_truth, _ = flown
    t, v = log.scalars("wind/north/truth")
    assert 8 <= len(t) <= 20, len(t)  # 5 Hz over ~2.5 s of simulation
    for ti, vi in zip(t, v, strict=True):  # every recorded truth row is one of the bridge's truth samples
        j = int(np.argmin(np.abs(t_truth - ti)))
        assert abs(t_truth[j] - ti) < 1e-6 and vi == pytest.approx(n_truth[j], abs=1e-9)
    assert np.mean(v) < -1.0  # open-field: 5 m/s from the north, the air moves south
    for e in ("wind/speed/truth", "wind/direction/truth", "world/vehicle", "chem/value", "rotors/1"):
        assert e in log.entity_paths() + log.series(), e


def test_windseeks_estimate_and_arducopters_own_on_the_same_plots(flown: tuple) -> None:
    log, _, _, _, t_msgs = flown
    for k, axis in enumerate(("north", "east", "down")):
        t, v = log.scalars(f"wind/{axis}/estimate")
        assert np.allclose(v, EST[k]) and len(t) == 3
        assert np.allclose(sorted(t), [t_msgs - 0.1, t_msgs - 0.05, t_msgs], atol=2e-6)
        _, lo, hi = log.band(f"wind/{axis}/band")
        s = 2.0 * math.sqrt(VAR_H / 2.0 if k < 2 else VAR_V)
        assert np.allclose(lo, EST[k] - s) and np.allclose(hi, EST[k] + s)
    ap_ned = (-AP_SPEED * math.cos(math.radians(AP_FROM_DEG)), -AP_SPEED * math.sin(math.radians(AP_FROM_DEG)), AP_Z)
    for k, axis in enumerate(("north", "east", "down")):
        t, v = log.scalars(f"wind/{axis}/autopilot")
        assert len(v) == 1 and v[0] == pytest.approx(ap_ned[k], abs=1e-6)
        assert t[0] >= t_msgs  # WIND has no time stamp: the vehicle's time it arrived
    assert log.scalars("wind/speed/autopilot")[1][0] == pytest.approx(AP_SPEED)
    assert log.scalars("wind/direction/autopilot")[1][0] % 360.0 == pytest.approx(AP_FROM_DEG)
    names = {e: log.column(e, "SeriesLines:names")[1][-1] for e in
             ("wind/north/autopilot", "wind/north/estimate", "wind/north/truth", "wind/direction/autopilot")}
    names = {e: n[0] if isinstance(n, list) else n for e, n in names.items()}
    assert names == {"wind/north/autopilot": "ArduCopter EKF3 N", "wind/north/estimate": "windseek UKF N",
                     "wind/north/truth": "truth N", "wind/direction/autopilot": "ArduCopter EKF3"}  # fmt: skip


def test_mission_mode_events_and_the_summary_with_both_sources(flown: tuple) -> None:
    log, runner_summary, _, _, _ = flown
    assert "GUIDED" in [s for _, s in log.states("phases/mode")]
    assert "surge" in [s for _, s in log.states("phases/strategy")]
    assert any("EKF3 IMU0 is using GPS" in x for _, x in log.texts("log/events"))
    s = log.summary()
    assert s is not None and s.declared_ned == pytest.approx([18.0, 1.0, -2.0])
    assert s.wind_scored == 3 and s.wind_rmse_ned_m_s is not None
    assert "ArduCopter EKF3 wind vs truth" in s.extra and "windseek UKF wind vs truth" in s.extra, s.extra
    score = json.loads(log.property_value("truth_score", "json"))
    assert score["wind_estimates_received"] == 3 and score["autopilot_wind"]["received"] == 1
    assert score["autopilot_wind"]["scored"] == 1 and score["wind_rmse_ned_m_s"] == runner_summary["wind_rmse_ned_m_s"]
    assert log.property_value("recording_cost", "recorder_cpu_s") is not None
