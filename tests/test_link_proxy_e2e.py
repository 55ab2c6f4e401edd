"""Searches through the link proxy: ``windseek sitl`` <-> ``windseek link-proxy`` <-> the MAVSDK runner.

The SITL streams to the proxy's ``a`` end (and to a listener that never sends, so it never keeps the
data link alive); the proxy forwards to the runner's ``udpin`` port with seeded faults
(``tests/link_proxy_rig.py``). Searches (``surge-cast``, live UKF wind, ``open-field-low``): with
duplicates and reordering a full one (arm, take-off, search, declaration within 5 m, landing, disarm);
at 30 % loss each way 120 s of search in control, then landing and disarm. Mission uploads:
``test_link_proxy_mission.py``; cuts: ``test_link_proxy_cuts.py``.

The SITL runs faster than real time (``--speed``). MAVSDK's heartbeats, which keep the autopilot's
data link alive, are paced by the wall clock (1 Hz), so at speed K the data-link timeout
(``COM_DL_LOSS_T``, 10 s of vehicle time) would see only 10 / K of them. Under loss the tests that
are not about the data-link failsafe set it to 10 K s, the same 10 heartbeats as in a real flight.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator
from dataclasses import replace

import pytest
from link_proxy_rig import Rig, assert_faulted_both_ways, assert_found_and_landed, make_rigs

from mission.runners.mavsdk_runner import run_mission
from mission.safety import SafetyLimits
from wire import param_codec
from wire.dialect import mavlink as mav
from wire.proxy import Faults

pytestmark = pytest.mark.e2e
pytest.importorskip("mavsdk")


@pytest.fixture
def rigs() -> Iterator[Callable[..., Rig]]:
    yield from make_rigs()


LOSS = Faults(loss=0.3)
DUP_REORDER = Faults(duplicate=0.2, reorder=0.2, latency_s=0.005, jitter_s=0.005)


# ---------------------------------------------------------------------- searches on a bad link
LOSS_SPEED = 2.0
#: PX4's offboard-loss timeout (COM_OF_LOSS_T, 1 s) counts vehicle time: at speed 2-3 only 0.3-0.5 s of wall
#: clock, shorter than a scheduling hiccup on a loaded 2-core machine. The searches scale it to 1 s of wall
#: clock, as on a real vehicle in real time (the runner's own rate under load: benchmarks/runner_under_load.py).
OFFBOARD_LOSS_WALL_S = 1.0


@pytest.mark.asyncio
async def test_a_search_at_30_percent_loss_each_way_stays_in_control_and_lands(rigs: Callable[..., Rig]) -> None:
    """30 % loss each way for a 120 s (vehicle) search: the link holds (one switch to offboard, never
    out of it, no data-link loss, setpoints at rate), the runner ends it as it says and lands and
    disarms the vehicle, and a declaration, if any, is within 5 m. Whether the search *finds* the
    source at this loss is not asserted: surge-cast can spend the whole flight verifying one
    candidate there (benchmarks/README.md "Searches over a lossy link"); the search at 20 %
    duplicates + 20 % reordering below must find it."""
    rig = rigs(LOSS, LOSS_SPEED, seed=2)
    # 10 MAVSDK heartbeats (see above); COM_DL_LOSS_T is INT32 in PX4 (whole seconds)
    rig.listener.set_param(rig.port, "COM_DL_LOSS_T", int(10 * LOSS_SPEED), param_codec.INT32)
    rig.listener.set_param(rig.port, "COM_OF_LOSS_T", OFFBOARD_LOSS_WALL_S * LOSS_SPEED)
    res = await asyncio.wait_for(run_mission(rig.config(limits=replace(SafetyLimits(), time_limit_s=120.0))), 150.0)
    print(res.to_dict())
    assert res.cause in ("declared", "time-limit"), res.reasons
    if res.cause == "declared":
        assert_found_and_landed(res)
    assert res.landed and res.disarmed and not res.link_lost
    assert res.setpoint_rate_hz >= 8.0 and res.tick_rate_hz >= 8.0, res.to_dict()
    rig.close_sitl()
    assert_faulted_both_ways(rig.pxp.close(), "dropped_loss", 0.25, 0.35)
    lis = rig.listener
    lis.wait(lambda: not lis.armed, 5.0, "the listener sees the disarm")
    assert lis.pos[2] > -0.2 and not any("Data link lost" in t for _, t in lis.texts)
    assert [m for _, m, _ in lis.modes].count("OFFBOARD") == 1  # never dropped out of the search


@pytest.mark.asyncio
async def test_search_completes_with_duplicates_and_reordering(rigs: Callable[..., Rig]) -> None:
    rig = rigs(DUP_REORDER, 3.0, seed=3)
    rig.listener.set_param(rig.port, "COM_OF_LOSS_T", OFFBOARD_LOSS_WALL_S * 3.0)
    res = await asyncio.wait_for(run_mission(rig.config()), 200.0)
    print(res.to_dict())
    assert_found_and_landed(res)
    rig.close_sitl()
    rep = rig.pxp.close()
    assert_faulted_both_ways(rep, "duplicated", 0.15, 0.25)
    assert_faulted_both_ways(rep, "reordered", 0.1, 0.25)
    lis = rig.listener
    lis.wait(lambda: not lis.armed, 5.0, "the listener sees the disarm")
    assert [m for _, m, _ in lis.modes].count("OFFBOARD") == 1


@pytest.mark.asyncio
async def test_a_late_offboard_heartbeat_is_not_leaving_offboard(rigs: Callable[..., Rig]) -> None:
    """Every HEARTBEAT from the vehicle is lost for 3 s (vehicle) from the switch to offboard on, while the
    rest of the telemetry flows: the switch is acknowledged, the vehicle flies offboard, but the runner
    has seen no heartbeat that says so. It must not take the mode of the last heartbeat it saw
    (AUTO.LOITER, from before the switch) for the vehicle leaving offboard. Found at 30 % loss each way:
    "ABORT (offboard-lost): the vehicle left offboard on its own (mode AUTO.LOITER)" 1.5 s after a switch
    whose heartbeats were lost, with the vehicle in offboard all along."""
    speed = 2.0
    rig = rigs(Faults(), speed, thread=True)
    px = rig.thread
    assert px is not None

    def say(line: str) -> None:
        rig.lines.append(line)
        if "starting the search" in line:  # the next thing the runner does is the switch to offboard
            px.set_faults("a->b", Faults(drop_ids=frozenset({mav.MAVLINK_MSG_ID_HEARTBEAT})))
            threading.Timer(3.0 / speed, px.set_faults, ("a->b", Faults())).start()

    cfg = replace(rig.config(limits=replace(SafetyLimits(), time_limit_s=15.0)), say=say)
    res = await asyncio.wait_for(run_mission(cfg), 90.0)
    print(res.to_dict(), rig.listener.modes)
    assert px.report()["a->b"]["dropped_filter"] >= 2  # the switch's heartbeat and a periodic one at least
    assert res.cause == "time-limit", res.reasons  # it searched until its time limit, then landed
    assert [m for _, m, _ in rig.listener.modes].count("OFFBOARD") == 1 and res.landed and res.disarmed
