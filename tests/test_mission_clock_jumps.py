"""The vehicle clock going back is said once, counted, and the count reported at the end (issue 31,
finding 9): a mission that received two vehicles' streams under one system id printed 1,202 "vehicle
clock went back" lines, one per message.

Two windseek SITLs (both system 1, their boot clocks 10 s apart) stream to one real UDP port where the
mission's real MAVSDK vehicle listens; their messages interleave, so the clock jumps back at nearly
every other message.
"""

from __future__ import annotations

import asyncio

import pytest
from link_support import free_port, running, scenario, udp_to

from mission.runners.mavsdk_vehicle import LinkConfig, MavsdkVehicle
from mission.vehicle import Wait


@pytest.mark.e2e
@pytest.mark.asyncio
async def test_two_vehicles_clock_jumps_are_said_once_and_counted() -> None:
    pytest.importorskip("mavsdk")
    port = free_port()
    lines: list[str] = []
    with running([udp_to(port)], scenario()) as first:
        cfg = LinkConfig(f"udpin://127.0.0.1:{port}", speed_hint=4.0)
        async with MavsdkVehicle(cfg, lines.append) as v:
            assert await v.wait(lambda: v.state.t > 10.0, 1e9, 20.0) == Wait.OK
            with running([udp_to(port)], scenario()):  # a second vehicle, system 1 too, its clock at 0
                assert await v.wait(lambda: v.counters["clock_resets"] > 20, 1e9, 20.0) == Wait.OK, lines
                await asyncio.sleep(0.5)
            n = v.counters["clock_resets"]
        assert first.error is None
    said = [x for x in lines if "vehicle clock went back" in x]
    assert len(said) == 2, said  # the first jump, and the count at the end
    assert said[0].startswith("mission: the vehicle clock went back from ") and "(reboot?)" in said[0]
    total = said[1]
    assert total.startswith(f"mission: the vehicle clock went back {n} times in all (said at the first only)")
    assert total.endswith("two vehicles' streams under system 1?")
