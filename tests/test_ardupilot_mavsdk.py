"""With ArduCopter SITL (``WINDSEEK_ARDUPILOT_BIN``; skipped without it) flying windseek's world: a plain MAVSDK
client on ArduCopter's SERIAL1 uploads a three-waypoint mission with a return to launch (MAVSDK's raw mission
plugin), takes off in GUIDED and flies it in AUTO in open-field's wind; windseek's sensor component reaches the
client through ArduPilot's routing (ESC_TELEMETRY_1_TO_4 and CHEM from component 158)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from ardupilot_support import ardupilot_with_windseek
from link_support import autopilot, first

from mission.runners import ardupilot
from sitl.world.sensors import HomeConfig, ned_to_geodetic

pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem  # noqa: E402

WAYPOINTS_NE = [(15.0, 0.0), (15.0, 15.0), (0.0, 15.0)]
ALT_M = 8.0


def _items() -> list[MissionItem]:
    """ArduPilot's mission: item 0 is home (overwritten by ArduPilot), then the waypoints (relative altitude) and a
    return to launch. (MAVSDK's high-level mission plugin refuses this plan for ArduPilot with INVALID_ARGUMENT;
    its raw mission plugin, which MAVSDK's own ArduPilot examples use, is the route.)"""
    wp, rel = 16, 6  # MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    pts = [(0.0, 0.0, 0.0), *((n, e, ALT_M) for n, e in WAYPOINTS_NE)]
    items = []
    for seq, (n, e, alt) in enumerate(pts):
        lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), HomeConfig())
        items.append(MissionItem(seq, rel if seq else 0, wp, int(seq == 0), 1, 0.0, 1.0, 0.0, float("nan"),
                                 int(round(lat * 1e7)), int(round(lon * 1e7)), float(alt), 0))  # fmt: skip
    items.append(MissionItem(len(pts), rel, 20, 0, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0, 0))  # NAV_RETURN_TO_LAUNCH
    return items


async def _guided_and_armed(direct: MavlinkDirectAsync, action: ActionAsync, timeout_s: float = 90.0) -> None:
    """GUIDED, then armed: both retried once a wall second while ArduCopter refuses (after boot GUIDED wants
    the EKF's position, "Mode change to GUIDED failed: requires position", and arming wants 10 s of
    consistent IMUs, "Arm: Gyros inconsistent")."""
    from mavsdk.plugins.action import ActionError
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    fields = {"target_system": 1, "target_component": 1, "command": 176, "confirmation": 0, "param1": 1.0,
              "param2": 4.0, "param3": 0.0, "param4": 0.0, "param5": 0.0, "param6": 0.0, "param7": 0.0}  # GUIDED
    guided = MavlinkMessage(message_name="COMMAND_LONG", target_system_id=1, target_component_id=1,
                            fields_json=json.dumps(fields))  # fmt: skip
    end = asyncio.get_running_loop().time() + timeout_s
    while True:
        ack = await asyncio.wait_for(direct.send_command(guided), 10.0)
        if json.loads(ack.fields_json or "{}").get("result") == 0:
            try:
                await action.arm()
                return
            except ActionError:
                pass
        if asyncio.get_running_loop().time() > end:
            raise AssertionError("ArduCopter would not switch to GUIDED and arm")
        await asyncio.sleep(1.0)


@pytest.mark.e2e
@pytest.mark.ardupilot
@pytest.mark.asyncio
async def test_mavsdk_flies_a_three_waypoint_auto_mission_on_arducopter(tmp_path: Path) -> None:
    with ardupilot_with_windseek(tmp_path, "open-field", speedup=5.0, seed=11) as run:
        async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
            drone = await autopilot(sdk, f"tcpout://127.0.0.1:{run.ports['companion']}", 60.0)
            assert drone is not None, "no ArduCopter heartbeat on SERIAL1"
            tel, action, mission = TelemetryAsync(drone), ActionAsync(drone), MissionRawAsync(drone)
            direct = MavlinkDirectAsync(drone)
            said: list[str] = []
            await ardupilot.request_streams(SimpleNamespace(target=(1, 1), direct=direct, say=said.append))
            assert "refused" not in said[-1], said
            esc = await first(direct.subscribe_message("ESC_TELEMETRY_1_TO_4"), lambda m: m.component_id == 158, 60.0,
                              "windseek's ESC telemetry through ArduPilot")  # fmt: skip
            assert esc.system_id == 1 and len(json.loads(esc.fields_json)["rpm"]) == 4
            await first(direct.subscribe_message("NAMED_VALUE_FLOAT"),
                        lambda m: m.component_id == 158 and "CHEM" in m.fields_json, 30.0, "CHEM")  # fmt: skip
            await first(tel.subscribe_health_all_ok(), bool, 120.0, "ArduCopter healthy on windseek's sensors")
            # ArduCopter starts AUTO on the ground only with the throttle up: take off in GUIDED first.
            await action.set_takeoff_altitude(ALT_M)
            await _guided_and_armed(direct, action)
            await action.takeoff()
            await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > ALT_M - 1.0, 60.0, "take-off")
            await mission.upload_mission(_items())
            await mission.start_mission()
            done = await first(mission.subscribe_mission_progress(), lambda p: p.current >= 4, 240.0,
                               "the three waypoints")  # fmt: skip
            assert done.total == 5
            await first(tel.subscribe_armed(), lambda a: not a, 240.0, "return to launch, landing and disarm")
    s = run.summary()
    assert s, run.windseek_text()[-2000:]
    assert not s["crashed"] and s["on_ground"] and not s["ardupilot_armed"] and not s["safety_pilot"], s
    assert s["max_touchdown_speed_m_s"] < 1.5 and s["resends"] == 0
    assert np.hypot(*s["final_position_ned_m"][:2]) < 3.0, s["final_position_ned_m"]  # back home
    assert s["path_length_m"] > 2 * 15 + 15 + 2 * ALT_M  # flew the square, up and down
    assert np.linalg.norm(s["wind_true_at_vehicle_ned_m_s"][:2]) > 2.0  # in wind
    assert not any(k.startswith("controls_") for k in s)  # every output set was valid
