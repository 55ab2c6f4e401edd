"""``windseek review``'s airborne time needs evidence of flight, not arming (issue 31, finding 1).

An ArduSub tlog (armed 16 s, depth within +-0.3 m) used to read "16.0 s airborne". The ArduSub log
itself is not among the shared logs (``shared/data/logs/SOURCES.md``), so the test writes one the
way ArduSub sends it: real MAVLink 2 frames packed by pymavlink's ardupilotmega dialect
(HEARTBEAT MAV_TYPE_SUBMARINE / MAV_AUTOPILOT_ARDUPILOTMEGA, GLOBAL_POSITION_INT with the depth as
relative altitude, SCALED_IMU, ATTITUDE), in the tlog record format. The real QuadPlane tlog, armed
in-air state too, must keep its airborne time: it climbs.
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as ap

from review.convert import review
from review.summary import format_summary

_LOGS = [Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "logs", Path("/work/shared/data/logs")]
LOGS = next((p.resolve() for p in _LOGS if (p / "SOURCES.md").is_file()), None)


def _write_tlog(path: Path, mav_type: int, height_m: list[float]) -> None:
    """10 Hz for 20 s: disarmed for 2 s, armed for 16 s, disarmed; ``height_m`` per sample [m, up]."""
    veh = ap.MAVLink(None, srcSystem=1, srcComponent=1)
    out = bytearray()
    for k in range(200):
        ms, t_us = 1000 + 100 * k, int((1.7e9 + 0.1 * k) * 1e6)
        frames = []
        if k % 10 == 0:
            armed = ap.MAV_MODE_FLAG_SAFETY_ARMED if 20 <= k < 180 else 0
            frames.append(veh.heartbeat_encode(mav_type, ap.MAV_AUTOPILOT_ARDUPILOTMEGA, armed | 1, 19, 4))
        frames.append(veh.global_position_int_encode(ms, 473_977_000, 85_456_000, 488_000 + int(1000 * height_m[k]),
                                                     int(1000 * height_m[k]), 0, 0, 0, 0))  # fmt: skip
        frames.append(veh.attitude_encode(ms, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0))
        frames.append(veh.scaled_imu_encode(ms, 0, 0, -1000, 0, 0, 0, 0, 0, 0))
        for m in frames:
            out += struct.pack(">Q", t_us) + m.pack(veh)
    path.write_bytes(bytes(out))


def _depth() -> list[float]:
    """A depth hold at 2 m: -2 m +- 0.3 m (relative altitude is negative under water)."""
    return [-2.0 + 0.3 * ((k % 7) - 3) / 3 for k in range(200)]


def test_armed_submarine_is_never_airborne(tmp_path: Path) -> None:
    path = tmp_path / "ardusub.tlog"
    _write_tlog(path, ap.MAV_TYPE_SUBMARINE, _depth())
    s = review(path, tmp_path / "sub.rrd").summary
    assert s["vehicle_type"] == "submarine"
    assert s["airborne_s"] == 0.0 and s["airborne_segments"] == 0, s
    assert s["wind_figure_reason"] == "not airborne: the vehicle is a submarine, which does not fly"
    assert any("submarine, which does not fly: 16.0 s" in n for n in s["notes"]), s["notes"]
    assert "0.0 s airborne in 0 segment(s)" in format_summary(s)


def test_armed_quadrotor_without_climb_is_not_airborne(tmp_path: Path) -> None:
    """Armed on the ground (height within +-0.3 m): not airborne; the same log with a 5 m climb is."""
    path = tmp_path / "ground.tlog"
    _write_tlog(path, ap.MAV_TYPE_QUADROTOR, [h + 2.0 for h in _depth()])
    s = review(path, tmp_path / "ground.rrd").summary
    assert s["airborne_from"] == "HEARTBEAT (armed)" and s["airborne_s"] == 0.0
    assert s["wind_figure_reason"] == "not airborne: armed, but no climb of 1 m or more shows a flight"
    climb = [0.0] * 30 + [min(5.0, 0.5 * k) for k in range(170)]
    _write_tlog(path, ap.MAV_TYPE_QUADROTOR, climb)
    s = review(path, tmp_path / "climb.rrd").summary
    assert s["airborne_segments"] == 1 and s["airborne_s"] == pytest.approx(16.0, abs=0.2), s


@pytest.mark.skipif(LOGS is None, reason="third-party logs not found at ../shared/data/logs")
def test_real_quadplane_armed_and_climbing_stays_airborne() -> None:
    from review.convert import read_flight

    assert LOGS is not None
    fd = read_flight(LOGS / "ardupilot-quadplane-sitl.tlog")
    assert fd.sources["in_air"] == "HEARTBEAT (armed)" and not fd.not_airborne
    assert sum(b - a for a, b in fd.airborne_segments()) > 150.0
