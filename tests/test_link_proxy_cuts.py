"""Link cuts during a search, end to end: ``windseek sitl`` <-> ``windseek link-proxy`` <-> the MAVSDK runner.

Cut lengths are vehicle seconds (the failsafes count vehicle time), read by a listener outside the
proxy: 5 s (the vehicle holds on the offboard loss; the runner waits for a fresh heartbeat and lands
it), 15 s (the data-link failsafe lands the vehicle; the runner reports it as it finds it and sends
it nothing), and for good (the runner gives up after its grace time; the vehicle lands by itself).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from link_proxy_rig import Rig, make_rigs
from pymavlink import mavutil

from mission.runners.mavsdk_runner import MissionResult, run_mission
from mission.safety import SafetyLimits
from wire.proxy import Faults

pytestmark = pytest.mark.e2e
pytest.importorskip("mavsdk")


@pytest.fixture
def rigs() -> Iterator[Callable[..., Rig]]:
    yield from make_rigs()


# ---------------------------------------------------------------------- cuts
#: Slower than the searches: the offboard-loss timeout (1 s of vehicle time) must stay well above the
#: runner's scheduling hiccups on a loaded machine, or the vehicle holds before the cut.
CUT_SPEED = 2.0
CUT_LIMITS = replace(SafetyLimits(), link_timeout_s=1.5)  # wall seconds without telemetry = a loss
#: What the runner may say to the autopilot: mode changes, arming, take-off, landing, setpoints.
COMMANDS = {176, 400, 22, 21, 20, 17}  # DO_SET_MODE, ARM_DISARM, NAV_TAKEOFF, NAV_LAND, NAV_RTL, NAV_LOITER_UNLIM


async def search_then_cut(rig: Rig, restore: Callable[[], bool] | None, **kw: Any) -> tuple[asyncio.Task[MissionResult],
                                                                                          float]:  # fmt: skip
    """Start the mission and cut the link 3 s (vehicle time) into the offboard search, until ``restore()``
    (None: for good) and the runner has said the link is lost (a shorter gap is no loss for it). Returns
    the mission task and the wall time of the restore (``time.time()``, the tlog's clock)."""
    lis = rig.listener
    task = asyncio.create_task(run_mission(rig.config(limits=CUT_LIMITS, **kw)))

    def searching() -> bool:
        return task.done() or (lis.mode == "OFFBOARD" and lis.modes[-1][0] + 3.0 < lis.t)

    await asyncio.to_thread(lis.wait, searching, 90.0, "3 s of offboard search")
    assert not task.done(), f"the mission ended before the cut: {task.result().reasons}"
    rig.t_cut = lis.t
    rig.pxp.cut()
    if restore is None:
        return task, math.inf

    def over() -> bool:
        return restore() and any(x.startswith("mission: ABORT (link-lost)") for x in rig.lines)

    await asyncio.to_thread(lis.wait, over, 60.0, "the end of the cut and the runner noticing")
    rig.t_back = lis.t
    rig.pxp.restore()
    return task, time.time()


def commands_after(tlog: Path, wall_t: float) -> list[str]:
    """Mode, arming, take-off and landing commands and offboard setpoints the SITL received after ``wall_t``."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    out = []
    while (m := log.recv_match(type=["COMMAND_LONG", "COMMAND_INT", "SET_MODE", "SET_POSITION_TARGET_LOCAL_NED"])):
        if m.get_srcSystem() != 1 and m._timestamp > wall_t and (m.get_type().startswith("SET_") or
                                                                  m.command in COMMANDS):  # fmt: skip
            out.append(f"{m.get_type()} {getattr(m, 'command', '')} at {m._timestamp - wall_t:+.2f} s")
    log.close()
    return out


@pytest.mark.asyncio
async def test_5_s_cut_vehicle_holds_runner_lands_it_after_a_fresh_heartbeat(rigs: Callable[..., Rig]) -> None:
    rig = rigs(Faults(), CUT_SPEED)
    task, _ = await search_then_cut(rig, lambda: rig.listener.t >= rig.t_cut + 5.0)
    res = await asyncio.wait_for(task, 60.0)
    lis = rig.listener
    lis.wait(lambda: not lis.armed, 10.0, "the disarm")
    print(res.to_dict(), lis.modes, lis.texts)
    during = [(t, m) for t, m, _ in lis.after(rig.t_cut) if t < rig.t_back]
    after = [(t, m) for t, m, _ in lis.after(rig.t_back)]
    # The vehicle: OFFBOARD -> hold on the offboard loss, and nothing else while cut (no data-link landing).
    assert [m for _, m in during] == ["AUTO.LOITER"] and during[0][0] - rig.t_cut < 2.0, during
    assert not any("Data link lost" in x for _, x in lis.texts) and rig.t_back - rig.t_cut < 10.0
    # The runner: saw the loss, waited for a fresh heartbeat, saw it holding, landed it.
    assert res.cause == "link-lost" and res.link_lost and res.landed and res.disarmed
    assert res.reasons[0].startswith("ABORT (link-lost): no telemetry for"), res.reasons
    assert "LINK: telemetry is back (mode AUTO.LOITER, armed)" in res.reasons, res.reasons
    assert [m for _, m in after][:1] == ["AUTO.LAND"] and after[0][0] > rig.t_back
    assert lis.pos[2] > -0.2


@pytest.mark.asyncio
@pytest.mark.parametrize("until", ["15 s and disarmed", "landing"])
async def test_15_s_cut_failsafe_lands_runner_reports_it_and_sends_nothing(rigs: Callable[..., Rig], tmp_path: Path,
                                                                          until: str) -> None:  # fmt: skip
    """The data-link failsafe fires 8-10 s (vehicle) into the cut, as the last MAVSDK heartbeat was up to 2 s
    before it, and the landing from 3 m and the disarm take about 6 s more: at 15 s the vehicle may still be
    descending. ``15 s and disarmed`` restores the link at 15 s or at the disarm, whichever comes later;
    ``landing`` restores it in the middle of the failsafe landing. Either way the runner reports the
    vehicle as it is and sends it nothing (no hold, no land, no setpoint)."""
    tlog = tmp_path / "cut.tlog"
    rig = rigs(Faults(), CUT_SPEED, tlog=tlog)
    lis = rig.listener
    if until == "landing":
        def restore() -> bool:
            return lis.mode == "AUTO.LAND" and lis.pos[2] < -1.0 and lis.t > lis.modes[-1][0] + 0.5
    else:
        def restore() -> bool:
            return lis.t >= rig.t_cut + 15.0 and not lis.armed
    task, wall_back = await search_then_cut(rig, restore)
    res = await asyncio.wait_for(task, 60.0)
    lis.wait(lambda: not lis.armed, 15.0, "the disarm")
    print(res.to_dict(), lis.modes, lis.texts, rig.t_back - rig.t_cut)
    during = [m for t, m, _ in lis.after(rig.t_cut) if t < rig.t_back]
    # The vehicle: hold (offboard loss), then its data-link failsafe landed it, all while cut.
    assert during[:2] == ["AUTO.LOITER", "AUTO.LAND"], lis.modes
    assert any(x.startswith("Data link lost: landing") for _, x in lis.texts)
    # The runner reports what it found when the link came back, as it was, and how it ended.
    assert res.cause == "link-lost" and res.link_lost and res.landed and res.disarmed, res.to_dict()
    if until == "landing":
        assert "LINK: telemetry is back (mode AUTO.LAND, armed)" in res.reasons, res.reasons
        assert rig.lines.index("mission: landed and disarmed") > rig.lines.index(
            "mission: LINK: telemetry is back (mode AUTO.LAND, armed)"), rig.lines  # it waited for the disarm
    else:
        assert [r for r in res.reasons if r.startswith("LINK:")][-2:] == [
            f"LINK: telemetry is back (mode {lis.mode}, disarmed)",
            "LINK: the vehicle already landed and disarmed (autopilot failsafe)"], res.reasons  # fmt: skip
    rig.close_sitl()
    # ... and sent the vehicle nothing once the link was back.
    assert commands_after(tlog, wall_back) == []


@pytest.mark.asyncio
async def test_permanent_cut_runner_gives_up_vehicle_lands_by_itself(rigs: Callable[..., Rig]) -> None:
    rig = rigs(Faults(), CUT_SPEED)
    task, _ = await search_then_cut(rig, None, link_grace_s=3.0)
    res = await asyncio.wait_for(task, 60.0)
    lis = rig.listener
    await asyncio.to_thread(lis.wait, lambda: not lis.armed, 60.0, "the failsafe landing and disarm")
    print(res.to_dict(), lis.modes, lis.texts)
    # The runner: gave up, and says the vehicle's state at the end is unknown (the last it saw is in the
    # reasons), not the stale "in the air, armed" of before the cut.
    assert res.cause == "link-lost" and res.link_lost
    assert res.landed is None and res.disarmed is None, res.to_dict()
    assert res.reasons[0].startswith("ABORT (link-lost): no telemetry for"), res.reasons
    assert res.reasons[-1].startswith("LINK: still down after 3 s: the autopilot's failsafe is in charge "
                                      "(last seen: mode OFFBOARD, armed, "), res.reasons
    assert [m for _, m, _ in lis.after(rig.t_cut)][:2] == ["AUTO.LOITER", "AUTO.LAND"]
    assert lis.pos[2] > -0.2 and not lis.armed
    rig.close_sitl()
    rep = rig.pxp.close()
    assert rep["cut_now"] and rep["cuts"][0]["end_s"] is None and rep["b->a"]["tx_units"] > 0
