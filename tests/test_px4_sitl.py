"""With PX4 (``WINDSEEK_PX4_BIN``; skipped without it): PX4 SITL flies windseek's world in lockstep.

A MAVSDK client on PX4's API link uploads and flies a three-waypoint mission with a return to launch
in open-field's wind (5 m/s from the north, moderate turbulence); windseek's sensor component reaches
the client through PX4's forwarding (ESC_STATUS and CHEM from component 158)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from link_support import autopilot, first
from px4_support import px4_with_windseek, wait_log

from sitl.world.sensors import HomeConfig, ned_to_geodetic

pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission import MissionAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.mission import MissionItem, MissionPlan  # noqa: E402

WAYPOINTS_NE = [(15.0, 0.0), (15.0, 15.0), (0.0, 15.0)]
ALT_M = 8.0


def _item(n: float, e: float) -> MissionItem:
    lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), HomeConfig())
    return MissionItem(latitude_deg=lat, longitude_deg=lon, relative_altitude_m=ALT_M, speed_m_s=4.0,
                       is_fly_through=False, acceptance_radius_m=1.0)  # fmt: skip


@pytest.mark.e2e
@pytest.mark.px4
@pytest.mark.asyncio
async def test_px4_flies_a_three_waypoint_mission_in_windseeks_wind(tmp_path: Path) -> None:
    with px4_with_windseek(tmp_path, "open-field", speed=0.0) as run:
        wait_log(run, "PX4 in lockstep", 120.0)
        async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
            drone = await autopilot(sdk, f"udpout://127.0.0.1:{run.ports['api']}", 60.0)
            assert drone is not None, "no PX4 heartbeat on the API link"
            tel, action, mission = TelemetryAsync(drone), ActionAsync(drone), MissionAsync(drone)
            direct = MavlinkDirectAsync(drone)
            esc = await first(direct.subscribe_message("ESC_STATUS"), lambda m: m.component_id == 158, 60.0,
                              "windseek's ESC_STATUS through PX4")  # fmt: skip
            assert esc.system_id == run.ports["sysid"] and len(json.loads(esc.fields_json)["rpm"]) == 4
            chem = await first(direct.subscribe_message("NAMED_VALUE_FLOAT"),
                               lambda m: m.component_id == 158 and "CHEM" in m.fields_json, 30.0, "CHEM")  # fmt: skip
            assert chem.system_id == run.ports["sysid"]
            await first(tel.subscribe_health_all_ok(), bool, 120.0, "PX4 healthy on windseek's sensors")
            await mission.set_return_to_launch_after_mission(True)
            await mission.upload_mission(MissionPlan([_item(n, e) for n, e in WAYPOINTS_NE]))
            await action.arm()
            await mission.start_mission()
            done = await first(mission.subscribe_mission_progress(), lambda p: p.current == p.total, 240.0,
                               "the three waypoints")  # fmt: skip
            assert done.total == 3
            await first(tel.subscribe_armed(), lambda a: not a, 240.0, "return to launch, landing and disarm")
            pos = await first(tel.subscribe_position_velocity_ned(), lambda p: True, 10.0, "position")
    s = run.summary()
    assert s, run.windseek_text()[-2000:]
    assert s["sync"] == "lockstep" and s["lockstep_timeouts"] == 0
    assert not s["crashed"] and s["on_ground"] and not s["px4_armed"] and not s["safety_pilot"]
    assert s["max_touchdown_speed_m_s"] < 1.5
    truth = np.array(s["final_position_ned_m"])
    assert np.hypot(*truth[:2]) < 3.0  # back home (truth), PX4's estimate agrees within a few m
    assert abs(pos.position.north_m - truth[0]) < 3.0 and abs(pos.position.east_m - truth[1]) < 3.0
    assert s["path_length_m"] > 2 * 15 + 15 + 2 * ALT_M  # flew the square, up and down
    assert np.linalg.norm(s["wind_true_at_vehicle_ned_m_s"][:2]) > 2.0  # in wind
    assert not any(k.startswith("controls_") for k in s)  # every PX4 output set was valid
    print(json.dumps({k: s[k] for k in ("sim_time_s", "lockstep_speed", "lockstep_us_per_step_windseek",
                                         "lockstep_us_per_step_px4", "path_length_m")}))  # fmt: skip
