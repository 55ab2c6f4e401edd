"""End-to-end over TCP with MAVSDK: mission upload and flight with progress and item-reached
events, return to launch and landing at the end of the mission, and the raw messages MAVSDK's
mavlink_direct plugin sees (ESC_STATUS in rpm, the chemical reading as NAMED_VALUE_FLOAT CHEM).
"""

from __future__ import annotations

import asyncio
import json
import math
import socket

import numpy as np
import pytest
from link_support import autopilot, first, free_port, running, scenario

from sitl.link import TcpServerTransport
from sitl.world.sensors import ned_to_geodetic
from vehicle.rotor_model import hover_rotor_speed

pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission import MissionAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.mission import MissionItem, MissionPlan  # noqa: E402

pytestmark = pytest.mark.e2e

PLUME = {
    "model": "gaussian",
    "sources": [{"position_ned": [12.0, 0.0, -3.0], "rate_g_s": 5.0}],
    "sensor": {"sample_rate_hz": 10.0, "time_constant_s": 0.2},
}


def _item(home: object, n: float, e: float, alt: float, **kw: object) -> MissionItem:
    lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), home)
    return MissionItem(latitude_deg=lat, longitude_deg=lon, relative_altitude_m=alt, is_fly_through=False,
                       acceptance_radius_m=0.5, **kw)  # fmt: skip


@pytest.mark.asyncio
async def test_mavsdk_tcp_mission_progress_rtl_and_direct_messages() -> None:
    port = free_port(socket.SOCK_STREAM)
    sc = scenario(plume=PLUME)
    with running([TcpServerTransport(port, "127.0.0.1")], sc) as link:
        sim = link.sim
        home = sim.scenario.sensors.home
        async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
            drone = await autopilot(sdk, f"tcpout://127.0.0.1:{port}", 10.0)
            assert drone is not None
            tel, action, mission = TelemetryAsync(drone), ActionAsync(drone), MissionAsync(drone)
            direct = MavlinkDirectAsync(drone)
            await first(tel.subscribe_health_all_ok(), bool, 10.0, "health all ok")

            # Raw messages through mavlink_direct: ESC_STATUS is our dialect's (not pymavlink's common).
            esc = await first(direct.subscribe_message("ESC_STATUS"), lambda m: True, 5.0, "ESC_STATUS")
            assert esc.system_id == 1 and esc.component_id == 1
            rpm = json.loads(esc.fields_json)["rpm"]
            assert len(rpm) == 4 and all(0 <= r < 100 for r in rpm)  # disarmed: rotors still (ESC noise only)

            plan = MissionPlan([
                _item(home, 0.0, 0.0, 3.0, vehicle_action=MissionItem.VehicleAction.TAKEOFF),
                _item(home, -6.0, 0.0, 3.0, speed_m_s=3.0),
                _item(home, -6.0, 4.0, 3.0, loiter_time_s=1.0),
            ])  # fmt: skip
            await mission.set_return_to_launch_after_mission(True)
            await mission.upload_mission(plan)
            assert len(sim.fc.mission) >= 4  # take-off, change speed, 2 waypoints, RTL
            n_items = len(sim.fc.mission)

            reached: list[int] = []
            progress: list[tuple[int, int]] = []
            chem: list[float] = []

            async def collect_reached() -> None:
                async for m in direct.subscribe_message("MISSION_ITEM_REACHED"):
                    reached.append(json.loads(m.fields_json)["seq"])

            async def collect_progress() -> None:
                async for p in mission.subscribe_mission_progress():
                    progress.append((p.current, p.total))

            async def collect_chem() -> None:
                async for m in direct.subscribe_message("NAMED_VALUE_FLOAT"):
                    f = json.loads(m.fields_json)
                    if f["name"].rstrip("\x00") == "CHEM":
                        chem.append(float(f["value"]))

            tasks = [asyncio.create_task(c()) for c in (collect_reached, collect_progress, collect_chem)]
            await action.arm()
            await mission.start_mission()
            # Flying downwind of the source at its height: the chemical sensor must see the plume.
            # In the air the ESC telemetry reads the hover rotor speed (rad/s of the model, in rpm).
            w_hover_rpm = hover_rotor_speed(sim.vehicle) * 60 / (2 * math.pi)

            def flying(m: object) -> bool:
                rpm = json.loads(m.fields_json)["rpm"]
                return abs(np.mean(rpm) / w_hover_rpm - 1.0) < 0.15 and not sim.on_ground

            await first(direct.subscribe_message("ESC_STATUS"), flying, 10.0, "hover rpm in ESC_STATUS")
            await first(tel.subscribe_armed(), lambda a: not a, 60.0, "mission, RTL, landing and disarm")
            # MAVSDK 4 calls the mission finished on MISSION_CURRENT.mission_state == COMPLETE (PX4 sends it
            # once the final RTL item has handed over to RTL mode).
            assert await mission.is_mission_finished()
            await asyncio.sleep(0.3)
            for t in tasks:
                t.cancel()
            # Every item reported reached in order, except the final RTL (handed over to RTL mode, as PX4).
            assert reached == list(range(n_items - 1)), reached
            currents = [c for c, _ in progress]
            assert currents == sorted(currents), "mission progress must never go back"
            assert progress[-1] == (len(plan.mission_items), len(plan.mission_items))
            assert chem and max(chem) > 0.0, "no CHEM reading above zero on a pass downwind of the source"
            assert np.hypot(*sim.position[:2]) < 2.0 and sim.on_ground and not sim.crashed
    assert link.counters["handler_errors"] == 0
