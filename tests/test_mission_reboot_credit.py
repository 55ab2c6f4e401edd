"""Who landed the vehicle while the link was down (issue 31, finding 8).

After PX4 was killed in the air, windseek's own safety landing brought the vehicle down (sitl/hil/guard.py)
and the PX4 started again came back disarmed; the mission said "the vehicle already landed and disarmed
(autopilot failsafe)". A restarted autopilot boots disarmed, so that landing was not its failsafe's.

Here the autopilot is windseek's SITL behind a real UDP socket and the mission's real MAVSDK vehicle:
it takes off, the SITL is stopped in the air (killed) and a fresh one starts on the ground, disarmed, its
boot clock at 0 (the restarted autopilot). The mission's link-loss handling must credit the restart.
"""

from __future__ import annotations

import contextlib

import pytest
from link_support import free_port, running, scenario, udp_to

from mission.loop import LoopConfig, MissionLoop
from mission.runners.live_wind import NoLiveWind
from mission.runners.mavsdk_vehicle import LinkConfig, MavsdkVehicle
from mission.safety import SafetyLimits
from mission.strategies import make_strategy
from mission.strategies.params import CommonParams
from mission.vehicle import Wait


@pytest.mark.e2e
@pytest.mark.asyncio
async def test_a_restarted_autopilot_is_not_credited_with_the_landing() -> None:
    pytest.importorskip("mavsdk")
    port = free_port()
    lines: list[str] = []
    with contextlib.ExitStack() as first:
        link = first.enter_context(running([udp_to(port)], scenario()))
        cfg = LinkConfig(f"udpin://127.0.0.1:{port}", speed_hint=4.0, link_timeout_s=1.0)
        async with MavsdkVehicle(cfg, lines.append) as v:
            st = v.state
            await v.arm()
            await v.takeoff(3.0)
            assert await v.wait(lambda: st.pos is not None and -st.pos[2] > 2.0 and st.t > 8.0, 30.0) == Wait.OK
            loop = MissionLoop(v, make_strategy("surge-cast"), CommonParams(), NoLiveWind(), SafetyLimits(),
                               LoopConfig(link_grace_s=20.0))  # fmt: skip
            assert link.sim.fc.armed and not link.sim.fc.on_ground
            first.close()  # the autopilot is killed in the air
            assert await v.wait(lambda: v.link_lost() is not None, 1e9, 10.0) == Wait.LINK_LOST
            with running([udp_to(port)], scenario()) as restarted:  # started again: on the ground, disarmed
                await loop._after_link_loss()
                assert not restarted.sim.fc.armed
    reasons = loop.result.reasons
    restarted_line = "LINK: the autopilot restarted while the link was down (its clock went back)"
    assert reasons[-1].startswith(restarted_line), reasons
    assert "windseek's safety landing" in reasons[-1]
    assert not any("(autopilot failsafe)" in r for r in reasons), reasons
    assert st.boots == 1 and v.counters["clock_resets"] == 1, lines
