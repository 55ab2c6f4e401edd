"""End-to-end: the SITL behind MAVLink, flown by the real MAVSDK (C++ core in the PyPI wheel).

Over UDP: connect, health, arm, take-off, offboard position and velocity control, the loss
of the offboard stream, return to launch, landing and the automatic disarm. Mission flight,
TCP, serial and the mavlink_direct messages are in the other test modules of this family.
"""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from link_support import autopilot, first, free_port, running, udp_to

from sitl.autopilot.flight_modes import Mode

mavsdk = pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import OffboardAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, LandedState  # noqa: E402

pytestmark = pytest.mark.e2e


def _gcs() -> Mavsdk:
    return Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))


@pytest.mark.asyncio
async def test_mavsdk_udp_arm_takeoff_offboard_rtl_land() -> None:
    port = free_port()
    with running([udp_to(port)]) as link:
        sim = link.sim
        async with _gcs() as sdk:
            drone = await autopilot(sdk, f"udpin://127.0.0.1:{port}", 10.0)
            assert drone is not None, f"no autopilot for MAVSDK: {link.endpoint.links[0].transport.stats}, t={sim.t}"
            tel, action, offb = TelemetryAsync(drone), ActionAsync(drone), OffboardAsync(drone)
            await first(tel.subscribe_health_all_ok(), bool, 10.0, "health all ok")
            home = await first(tel.subscribe_home(), lambda h: math.isfinite(h.latitude_deg), 5.0, "home")
            assert home.latitude_deg == pytest.approx(sim.scenario.sensors.home.lat_deg, abs=1e-6)

            await action.arm()
            await first(tel.subscribe_armed(), bool, 5.0, "armed")
            await action.takeoff()
            await first(tel.subscribe_flight_mode(), lambda m: m == FlightMode.TAKEOFF, 5.0, "TAKEOFF mode")
            await first(tel.subscribe_flight_mode(), lambda m: m == FlightMode.HOLD, 20.0, "HOLD after take-off")
            pos = await tel.position()
            assert pos.relative_altitude_m == pytest.approx(3.0, abs=0.5)
            assert sim.position[2] == pytest.approx(-3.0, abs=0.5)

            # Offboard position: PX4 wants the setpoint stream before the mode switch.
            target = PositionNedYaw(4.0, -3.0, -4.0, 90.0)
            await offb.set_position_ned(target)
            await offb.start()
            await first(tel.subscribe_flight_mode(), lambda m: m == FlightMode.OFFBOARD, 5.0, "OFFBOARD")
            assert sim.fc.mode == Mode.OFFBOARD

            def near(p: object) -> bool:
                return abs(p.north_m - 4.0) < 0.4 and abs(p.east_m + 3.0) < 0.4 and abs(p.down_m + 4.0) < 0.4

            def settled(x: object) -> bool:
                v = x.velocity
                return near(x.position) and math.hypot(v.north_m_s, v.east_m_s, v.down_m_s) < 0.3

            await first(tel.subscribe_position_velocity_ned(), settled, 25.0, "offboard position reached, settled")
            assert sim.position == pytest.approx(np.array([4.0, -3.0, -4.0]), abs=0.6)
            yaw = (await tel.attitude_euler()).yaw_deg
            assert yaw == pytest.approx(90.0, abs=5.0)

            # Offboard velocity: east at 1.5 m/s.
            await offb.set_velocity_ned(VelocityNedYaw(0.0, 1.5, 0.0, 90.0))
            v = await first(tel.subscribe_velocity_ned(), lambda v: abs(v.east_m_s - 1.5) < 0.2, 10.0, "1.5 m/s east")
            assert abs(v.north_m_s) < 0.5
            await asyncio.sleep(0.5)
            assert sim.velocity[1] == pytest.approx(1.5, abs=0.3)

            # Stop offboard (MAVSDK switches to hold): the vehicle brakes and holds.
            await offb.stop()
            await first(tel.subscribe_flight_mode(), lambda m: m == FlightMode.HOLD, 5.0, "HOLD after offboard")

            await action.return_to_launch()
            await first(tel.subscribe_flight_mode(), lambda m: m == FlightMode.RETURN_TO_LAUNCH, 5.0, "RTL")
            await first(tel.subscribe_landed_state(), lambda s: s == LandedState.LANDING, 40.0, "landing at home")
            await first(tel.subscribe_armed(), lambda a: not a, 30.0, "disarmed after landing")
            # RTL starts the descent within 1 m of home (flight_modes) and drifts a little in the wind.
            assert np.hypot(*sim.position[:2]) < 2.0
            assert sim.on_ground and not sim.crashed
            # EXTENDED_SYS_STATE runs at the 1 Hz MAVSDK asked for: the landed state follows within a second.
            await first(tel.subscribe_landed_state(), lambda s: s == LandedState.ON_GROUND, 3.0, "on ground")
    assert link.counters["rx_bad"] == 0
    assert link.counters["handler_errors"] == 0
