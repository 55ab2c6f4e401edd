"""A fixed check flight through MAVSDK: take off, hover, fly waypoints at a bounded speed, land, and record the
WIND_COV the autopilot forwards (a ``windseek estimator`` on another of its links). It checks an estimator
on a vehicle without a wind truth: in still air (PX4 SIH has no wind model) the wind must stay near zero.

The waypoints are flown by offboard velocity setpoints toward each (speed ``speed_m_s``, slowing within
``speed_m_s / gain`` metres), so the airspeed stays inside what an identification flight covered; a leg that
does not arrive within its time is an abort, as is a link loss; every wait is bounded, and the vehicle
holds, then lands. Units m, m/s, s of vehicle time; NED (the autopilot's local frame) relative to home.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mission.result import MissionError
from mission.runners.mavsdk_vehicle import LinkConfig, MavsdkVehicle
from mission.runners.takeoff import takeoff_above_home
from mission.vehicle import CommandError, Wait


@dataclass
class CheckFlightConfig:
    """connect: MAVSDK URL; altitude_m above home; hover_s: the hover after take-off; waypoints_ne: (north,
    east) m from home, flown in order at ``altitude_m``; speed_m_s: the horizontal speed; gain (1/s): the
    velocity per metre of distance near a waypoint; speed_hint: the simulator's speed factor."""

    connect: str
    altitude_m: float = 10.0
    hover_s: float = 30.0
    waypoints_ne: tuple[tuple[float, float], ...] = ((25.0, 0.0), (25.0, 25.0), (0.0, 0.0))
    speed_m_s: float = 2.5
    gain: float = 0.8
    dwell_s: float = 3.0
    speed_hint: float = 1.0
    connect_timeout_s: float = 30.0
    health_timeout_s: float = 60.0
    takeoff_timeout_s: float = 60.0
    land_timeout_s: float = 120.0
    say: Callable[[str], None] = print


@dataclass
class CheckFlightResult:
    """Phases (name -> (t0, t1) s of the autopilot's clock), the forwarded WIND_COV rows (t, north, east, down
    m/s, var_horiz m^2/s^2), the abort line (None: none) and how the vehicle ended."""

    phases: dict[str, tuple[float, float]] = field(default_factory=dict)
    wind: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    takeoff_t_s: float = math.nan
    abort: str | None = None
    disarmed: bool | None = None

    def wind_in(self, phase: str) -> np.ndarray:
        """The WIND_COV rows (n, 5) inside a phase."""
        t0, t1 = self.phases[phase]
        rows = [r for r in self.wind if t0 <= r[0] <= t1]
        return np.array(rows) if rows else np.zeros((0, 5))


async def fly_check(cfg: CheckFlightConfig) -> CheckFlightResult:
    """Fly the check flight (see the module docstring). MissionError when it cannot start."""
    res = CheckFlightResult()

    def sink(name: str, f: dict[str, Any], t: float, sysid: int, compid: int) -> None:
        if name == "WIND_COV" and all(k in f for k in ("wind_x", "wind_y", "wind_z", "var_horiz")):
            res.wind.append((f["time_usec"] * 1e-6, float(f["wind_x"]), float(f["wind_y"]), float(f["wind_z"]),
                             float(f["var_horiz"])))  # fmt: skip

    link = LinkConfig(cfg.connect, cfg.connect_timeout_s, cfg.health_timeout_s, 3.0, cfg.speed_hint)
    async with MavsdkVehicle(link, cfg.say, sink, ("WIND_COV",)) as v:
        st = v.state
        assert st.pos is not None
        if st.armed:
            raise MissionError("the vehicle is already armed: start the check flight on the ground")
        home = st.pos.copy()
        await _arm(v)
        why = await takeoff_above_home(v, cfg.altitude_m)
        if why is not None:
            res.abort = why
            await _land(v, cfg)
            return res
        up = await v.wait(lambda: st.pos is not None and st.mode == "AUTO.LOITER"
                          and home[2] - st.pos[2] > cfg.altitude_m - 0.7, cfg.takeoff_timeout_s)  # fmt: skip
        if up != Wait.OK:
            res.abort = f"take-off did not finish ({up.value}, mode {st.mode})"
        else:
            res.takeoff_t_s = st.t
            v.say(f"check flight: take-off complete at t = {st.t:.2f} s; hovering {cfg.hover_s:g} s")
            t0 = st.t
            await v.wait(lambda: st.t - t0 >= cfg.hover_s, cfg.hover_s)
            res.phases["hover"] = (t0, st.t)
            res.abort = await _waypoints(v, cfg, home, res)
        if res.abort:
            v.say(f"check flight: ABORT: {res.abort}")
        await _land(v, cfg)
        res.disarmed = None if v.link_lost() else not st.armed
    return res


async def _waypoints(v: MavsdkVehicle, cfg: CheckFlightConfig, home: np.ndarray, res: CheckFlightResult
                     ) -> str | None:  # fmt: skip
    st = v.state
    assert st.pos is not None
    v.send_setpoint(None, np.zeros(3), st.yaw)
    try:
        await v.start_offboard()
    except CommandError as e:
        return f"offboard refused: {e}"
    t0 = st.t
    down = home[2] - cfg.altitude_m
    for i, (north, east) in enumerate(cfg.waypoints_ne):
        target = np.array([home[0] + north, home[1] + east, down])
        assert st.pos is not None
        leg_s = 20.0 + 2.0 * float(np.linalg.norm(target - st.pos)) / cfg.speed_m_s
        t_leg, t_next, arrived = st.t, st.t, math.nan
        while True:
            got = await v.next_tick(t_next)
            if got == Wait.LINK_LOST:
                return v.link_lost() or "link lost"
            if got == Wait.TIMEOUT:
                continue
            t_next = st.t + 0.05
            err = target - st.pos
            dist = float(np.linalg.norm(err[0:2]))
            if dist < 1.0 and math.isnan(arrived):
                arrived = st.t
            if not math.isnan(arrived) and st.t - arrived >= cfg.dwell_s:
                break
            if st.t - t_leg > leg_s:
                return f"waypoint {i + 1} not reached within {leg_s:.0f} s ({dist:.1f} m away)"
            vel = err * cfg.gain
            h = float(np.linalg.norm(vel[0:2]))
            if h > cfg.speed_m_s:
                vel[0:2] *= cfg.speed_m_s / h
            vel[2] = float(np.clip(vel[2], -1.0, 1.0))
            try:
                v.send_setpoint(None, vel, st.yaw)
            except CommandError as err:
                return str(err)
        v.say(f"check flight: waypoint {i + 1} at t = {st.t:.2f} s")
    res.phases["waypoints"] = (t0, st.t)
    return None


#: Wall seconds a check flight retries an arming its autopilot refuses (preflight checks settling after boot).
ARM_RETRY_S = 30.0


async def _arm(v: MavsdkVehicle) -> None:
    """Arm; a refusal is retried once a wall second for :data:`ARM_RETRY_S` (PX4 refuses while its heading
    estimate settles after boot, "Preflight Fail: heading estimate not stable", seen on a loaded machine)."""
    end = time.monotonic() + ARM_RETRY_S
    while True:
        try:
            await v.arm()
            return
        except CommandError as e:
            if time.monotonic() > end:
                raise MissionError(f"{e} (refused for {ARM_RETRY_S:g} s)") from None
        await asyncio.sleep(1.0)


async def _land(v: MavsdkVehicle, cfg: CheckFlightConfig) -> None:
    st = v.state
    if not st.armed:
        return
    with contextlib.suppress(CommandError):
        if st.mode == "OFFBOARD":
            await v.stop_offboard()
        await v.land()
    got = await v.wait(lambda: not st.armed, cfg.land_timeout_s)
    v.say("check flight: landed and disarmed" if got == Wait.OK else f"check flight: not disarmed ({got.value})")
