"""The MAVSDK runner on a bad link: its commands through the link proxy to the in-process SITL, and its
estimator watch under duplicated and reordered telemetry.

MAVSDK sends a command four times, 0.5 s apart, and gives up (TIMEOUT). At 30 % loss each way a
round trip succeeds with probability 0.49, so one command in 15 times out; a mission sends several.
The runner sends a command that timed out again (``COMMAND_ATTEMPTS`` in all, never after a
refusal, never once the link counts as lost). Here the ground-to-vehicle direction drops everything
for 3 s, longer than MAVSDK's own retries: the arm must still happen, and the retry be counted.
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest
from link_support import free_port, running, scenario

from mission.runners.mavsdk_vehicle import LinkConfig, MavsdkVehicle
from mission.safety import EstimatorWatch
from mission.vehicle import CommandError
from sitl.link import UdpTransport
from wire.proxy import Faults, LinkProxy


def test_duplicated_or_reordered_inputs_are_not_an_estimator_fault() -> None:
    """A link that duplicates or reorders datagrams makes the UKF discard samples it already has (or that
    come too late): right, counted, and no fault. Found through the proxy: at 20 % duplication a search
    aborted with "53 estimator inputs rejected within 2 s (most: imu:duplicate_or_out_of_order)". A real
    fault still counts, and a stream that only ever repeats itself still ends in "no IMU sample"."""
    w, cov = np.array([-5.0, 0.0, 0.0]), np.eye(3) * 0.1
    ew = EstimatorWatch(burst=20, window_s=2.0, input_timeout_s=1.0)
    stale = ("imu:duplicate_or_out_of_order", "attitude:duplicate_or_out_of_order",
             "rotors:duplicate_or_out_of_order", "gnss:duplicate_or_out_of_order", "imu:older_than_filter")  # fmt: skip
    for k in range(20):
        assert ew.check(0.1 * k, w, cov, dict.fromkeys(stale, 30 * k), imu_accepted=100 * (k + 1)) is None
    a = ew.check(2.0, w, cov, dict.fromkeys(stale, 600) | {"imu:bad_value": 25}, imu_accepted=2100)
    assert a is not None and "imu:bad_value" in a.message
    ew = EstimatorWatch(input_timeout_s=1.0)
    assert ew.check(0.0, w, cov, {}, 10) is None
    a = ew.check(1.2, w, cov, {"imu:duplicate_or_out_of_order": 500}, 10)
    assert a is not None and "no IMU sample" in a.message



BLACKOUT_S = 3.0


@pytest.mark.e2e
@pytest.mark.asyncio
async def test_a_command_lost_longer_than_mavsdk_retries_is_sent_again() -> None:
    pytest.importorskip("mavsdk")
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
