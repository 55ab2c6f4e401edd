"""ArduCopter SITL flies windseek's world (``windseek sitl --ardupilot``): a real ArduCopter built from source
(``WINDSEEK_ARDUPILOT_BIN``; skipped without it), driven by a plain pymavlink ground station as MAVProxy would:
arm in GUIDED, take off, a 3-waypoint AUTO mission ending in a LAND item, in the scenario's wind."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from ardupilot_support import CopterGcs, ardupilot_with_windseek

from recording.read import RrdLog
from review.convert import review
from sitl.scenario import load_scenario
from wire.dialect import mavlink as M  # noqa: N812

pytestmark = [pytest.mark.e2e, pytest.mark.ardupilot]


def _square(scenario: str, side_m: float, alt_m: float) -> list[tuple[int, float, float, float]]:
    h = load_scenario(scenario).sensors.home
    dn = 1.0 / 111320.0
    de = dn / math.cos(math.radians(h.lat_deg))
    lat, lon = h.lat_deg, h.lon_deg
    wp = M.MAV_CMD_NAV_WAYPOINT
    return [(wp, lat + side_m * dn, lon, alt_m), (wp, lat + side_m * dn, lon + side_m * de, alt_m),
            (wp, lat, lon + side_m * de, alt_m), (M.MAV_CMD_NAV_LAND, lat, lon, 0.0)]  # fmt: skip


def test_arducopter_flies_an_auto_mission_in_windseeks_wind(tmp_path: Path) -> None:
    with ardupilot_with_windseek(tmp_path, "open-field-low", speedup=5.0, seed=3) as run:
        g = CopterGcs(run.ports["gcs"])
        try:
            hb = g.recv("HEARTBEAT", 30.0, lambda h: h.get_srcComponent() == 1)
            assert hb is not None and hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA, run.ardupilot.log_text()[-2000:]
            g.m.target_system = hb.get_srcSystem()
            g.request_streams(10)
            assert g.arm_when_ready("GUIDED") == 0, g.text[-10:]
            r = g.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0)
            assert r == 0, " / ".join(g.text)  # before auto-disarm
            # (Uploaded once ArduCopter is ready: at boot it answers MAV_MISSION_NO_SPACE until its storage is up.)
            assert g.upload_mission(_square("open-field-low", 15.0, 5.0)) == M.MAV_MISSION_ACCEPTED, g.text[-10:]
            assert g.recv("GLOBAL_POSITION_INT", 30.0, lambda p: p.relative_alt > 4000) is not None, g.text[-10:]
            assert g.set_mode("AUTO") == 0
            reached: list[int] = []
            disarmed = None
            while disarmed is None:
                m = g.recv(["MISSION_ITEM_REACHED", "HEARTBEAT"], 60.0)
                assert m is not None, (reached, g.text[-10:])
                if m.get_type() == "MISSION_ITEM_REACHED":
                    reached.append(int(m.seq))
                elif m.get_srcComponent() == 1 and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED and reached:
                    disarmed = m
            assert reached[:3] == [1, 2, 3], reached
            assert any("Land" in t for t in g.text), g.text[-10:]
        finally:
            g.close()
    s = run.summary()
    text = run.windseek_text()
    assert s, text[-2000:]
    # windseek's truth: back on the ground at home, not crashed, a soft touchdown, a 15 m square flown.
    assert not s["crashed"] and s["on_ground"] and not s["ardupilot_armed"] and not s["safety_pilot"], s
    assert math.hypot(*s["final_position_ned_m"][:2]) < 2.0, s["final_position_ned_m"]
    assert s["max_touchdown_speed_m_s"] < 1.5 and s["path_length_m"] > 55.0, s
    assert s["resends"] == 0 and s["restarts"] == 0 and s["frames"] > 30000, s
    assert "ArduPilot connected" in text
    # ArduCopter's own DataFlash log of the flight, reviewed: EKF3's wind (XKF2) beside windseek's UKF in the
    # recording (with ArduPilot's defaults EKF3 estimates no wind: its wind reads ~0 in the 5 m/s).
    logs = sorted((tmp_path / "ardupilot" / "logs").glob("*.BIN"))
    assert logs, "ArduCopter wrote no DataFlash log"
    r = review(logs[-1], tmp_path / "review.rrd")
    assert r.summary["sources"]["autopilot_wind"].startswith("XKF2"), r.summary["sources"]
    _, ap_n = RrdLog(r.out).scalars("wind/north/autopilot")
    _, est_n = RrdLog(r.out).scalars("wind/north/estimate")
    assert len(ap_n) > 100 and len(est_n) > 100 and np.nanmean(est_n) < -2.0  # the UKF sees the north wind
