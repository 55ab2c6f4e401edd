"""The MAVSDK runner's commands on a bad link, through the link proxy to the in-process SITL.

MAVSDK sends a command four times, 0.5 s apart, and gives up (TIMEOUT). At 30 % loss each way a
round trip succeeds with probability 0.49, so one command in 15 times out; a mission sends several.
The runner sends a command that timed out again (``COMMAND_ATTEMPTS`` in all, never after a
refusal, never once the link counts as lost). Here the ground-to-vehicle direction drops everything
for 3 s, longer than MAVSDK's own retries: the arm must still happen, and the retry be counted.
"""

from __future__ import annotations

import asyncio
import time

import pytest
from link_support import free_port, running, scenario

from mission.runners.mavsdk_vehicle import LinkConfig, MavsdkVehicle
from mission.vehicle import CommandError
from sitl.link import UdpTransport
from wire.proxy import Faults, LinkProxy

pytestmark = pytest.mark.e2e
pytest.importorskip("mavsdk")

BLACKOUT_S = 3.0


@pytest.mark.asyncio
async def test_a_command_lost_longer_than_mavsdk_retries_is_sent_again() -> None:
    mport = free_port()
    proxy = LinkProxy("udpin:127.0.0.1:0", f"udpout:127.0.0.1:{mport}", seed=1).start()
    lines: list[str] = []
    try:
        with running([UdpTransport([("127.0.0.1", proxy.a.port)], ("127.0.0.1", 0))], scenario()) as link:
            cfg = LinkConfig(f"udpin://127.0.0.1:{mport}", speed_hint=4.0, link_timeout_s=10.0)
            async with MavsdkVehicle(cfg, lines.append) as v:
                # A refusal is not retried: offboard without a setpoint is refused at once.
                with pytest.raises(CommandError, match="offboard: NO_SETPOINT_SET"):
                    await v.start_offboard()
                assert v.counters["command_retries"] == 0
                proxy.set_faults("b->a", Faults(loss=1.0))
                t0 = time.monotonic()
                arm = asyncio.create_task(v.arm())
                await asyncio.sleep(BLACKOUT_S)
                proxy.set_faults("b->a", Faults())
                await asyncio.wait_for(arm, 20.0)
                assert time.monotonic() - t0 >= BLACKOUT_S  # it cannot have got through the blackout
                assert link.sim.fc.armed
                assert v.counters["command_retries"] >= 1
    finally:
        rep = proxy.report()
        proxy.stop()
    assert rep["b->a"]["dropped_loss"] >= 4, rep  # MAVSDK's four attempts (and its heartbeats) were lost
