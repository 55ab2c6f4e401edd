"""The one mission loop: take-off, wind wait, strategy ticks under the safety supervisor, declaration,
landing; the same for the lockstep simulator and for a real autopilot through MAVSDK.

:class:`MissionLoop` flies a strategy through a :class:`~mission.vehicle.Vehicle` with a
:class:`MissionWind` source:

1. home = the vehicle's position on the ground; the search altitude is clamped into the limits;
2. arm, take off, wait (vehicle time) until holding in the air at the altitude;
3. hover until the wind source gives a usable direction (at most ``wind_wait_s``); an estimator
   that never started is an ``estimator-fault``, not a zero wind;
4. at every strategy tick (``rate_hz`` of vehicle time): the safety checks (crash, time limit,
   geofence, wind-source fault, disarmed, left offboard, link), the observation, the strategy, the
   setpoint clamped into the limits and sent (offboard starts after the first one);
5. the strategy done with a declaration: fly over it and land there (``land_at_end``), or stop
   (batch evaluation); an abort: hold, then land; a link loss: leave the vehicle to its own
   failsafe, and if the link comes back, look at the vehicle again before doing anything (a vehicle
   found disarmed is credited to the autopilot's failsafe only if the autopilot did not restart meanwhile).

Every decision reads the vehicle's own state (:class:`~mission.vehicle.VehicleState`), and the result
says what happened (:class:`~mission.result.MissionResult`). Units SI, NED; vehicle time.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from mission.obstacles import Obstacles
from mission.result import MissionError, MissionResult
from mission.safety import Abort, SafetyLimits, Supervisor
from mission.strategies.base import Observation, Setpoint, Strategy, WindInfo
from mission.strategies.params import CommonParams
from mission.vehicle import LANDED_IN_AIR, LANDED_ON_GROUND, CommandError, Vehicle, Wait
from wire.names import declaration_fields, state_fields


class MissionWind(Protocol):
    """Where the strategy's wind comes from (estimated, oracle, WIND_COV, none)."""

    mode: str

    def info(self, t: float) -> WindInfo | None:
        """The wind for the strategy tick at vehicle time ``t`` (once per tick; None: no wind mode)."""
        ...

    def ready(self) -> bool:
        """A real estimate exists (False: the estimator has not started, or nothing has arrived)."""
        ...

    def missing(self) -> str:
        """One line: what the source lacks while not ready."""
        ...

    def fault(self, t: float) -> Abort | None:
        """An ``estimator-fault`` abort, or None."""
        ...

    def describe(self) -> str:
        """One line: which source and inputs it uses."""
        ...

    def report(self) -> dict[str, Any]:
        """Counters for the result (accepted, rejected, dropped inputs, restarts ...)."""
        ...


#: Vehicle seconds after an accepted switch to offboard within which a HEARTBEAT must show it (they come
#: at 1 Hz, and several in a row may be lost on a bad link: at 30 % loss five in a row 0.24 % of the time, which
#: aborted a search in a fresh-clone CI run with the OFFBOARD heartbeat arriving just after; ten 6e-6). The
#: vehicle holds in its previous mode until then, so waiting longer costs nothing but time.
OFFBOARD_CONFIRM_S = 10.0
#: How long the runner keeps asking for offboard control while the autopilot denies it (s of vehicle time).
OFFBOARD_RETRY_S = 3.0


@dataclass
class LoopConfig:
    """Timing of a mission (vehicle seconds unless named wall).

    takeoff_timeout_s: the take-off must end within this; land_timeout_s: landing and disarm.
    hold_s: hold before landing after an abort. link_grace_s: wall seconds to wait for a lost link.
    land_at_end: after a declaration, fly over it and land (False: stop, as batch evaluation does).
    """

    takeoff_timeout_s: float = 40.0
    land_timeout_s: float = 90.0
    hold_s: float = 2.0
    link_grace_s: float = 30.0
    land_at_end: bool = True


class MissionLoop:
    """One mission (see the module docstring). ``on_tick(t)`` is called at every search tick (scoring);
    ``obstacles``: buildings no setpoint may lead into (the supervisor clamps around them)."""

    def __init__(self, vehicle: Vehicle, strategy: Strategy, params: CommonParams, wind: MissionWind,
                 limits: SafetyLimits, cfg: LoopConfig | None = None, seed: int = 0,
                 on_tick: Callable[[float], None] | None = None,
                 obstacles: Obstacles | None = None) -> None:  # fmt: skip
        limits.validate()
        self.v = vehicle
        self.strategy = strategy
        self.params = params
        self.wind = wind
        self.limits = limits
        self.cfg = cfg or LoopConfig()
        self.seed = seed
        self.on_tick = on_tick
        self.obstacles = obstacles
        self.result = MissionResult(strategy=str(getattr(strategy, "name", "")), wind=wind.mode)
        self.sup: Supervisor | None = None
        self.t_arm = math.nan
        self.t_declared = math.nan
        self._wind_info: WindInfo | None = None
        self._published = ""
        self._declared_sent = False
        self._offboard_seen = False

    @property
    def wind_info(self) -> WindInfo | None:
        """The wind the strategy got at the latest tick (None: none yet, or no wind mode)."""
        return self._wind_info

    # ------------------------------------------------------------------ lines
    def say(self, line: str) -> None:
        if line.startswith(("ABORT", "LINK", "SAFETY")):
            self.result.reasons.append(line)
        self.v.say(f"mission: {line}")

    # ------------------------------------------------------------------ the mission
    async def run(self) -> MissionResult:
        """Fly the mission; raises :class:`MissionError` only when it cannot start."""
        st = self.v.state
        if st.pos is None:
            raise MissionError("no position from the vehicle")
        if st.armed or st.landed == LANDED_IN_AIR:
            raise MissionError("the vehicle is already armed or flying: start the mission on the ground, disarmed")
        home = st.pos.copy()
        self.result.home_ned = [round(float(v), 3) for v in home]
        self.result.wind_source = self.wind.describe()
        self.sup = Supervisor(self.limits, home, self.obstacles)
        alt = self.sup.altitude_target(self.params.altitude_m)
        if alt != self.params.altitude_m:
            self.say(f"SAFETY: search altitude {self.params.altitude_m:g} m clamped to {alt:g} m by the limits")
        set_obstacles = getattr(self.strategy, "set_obstacles", None)
        if set_obstacles is not None:  # a strategy that plans with the buildings (infotaxis' urban model)
            set_obstacles(self.obstacles)
        self.strategy.reset(home, self.params, seed=self.seed)
        try:
            await self.v.arm()
            self.t_arm = st.t
            self.say(f"armed at t = {self.t_arm:.2f} s; taking off to {alt:g} m")
            await self.v.takeoff(alt)
        except CommandError as e:
            raise MissionError(str(e)) from None
        abort = await self._take_off(home, alt)
        if abort is None:
            abort = await self._search()
        if abort is not None:
            await self._abort(abort)
        elif self.cfg.land_at_end:
            await self._land_at_declared()
        else:
            self.result.cause = "declared"
        self._final()
        return self.result

    async def _take_off(self, home: np.ndarray, alt: float) -> Abort | None:
        st = self.v.state

        def airborne() -> bool:
            return (st.mode == "AUTO.LOITER" and st.landed == LANDED_IN_AIR and st.pos is not None
                    and abs(-(st.pos[2] - home[2]) - alt) < 0.5)  # fmt: skip

        done = await self.v.wait(airborne, self.cfg.takeoff_timeout_s)
        if done == Wait.LINK_LOST:
            return Abort("link-lost", self.v.link_lost() or "link lost during the take-off")
        if done != Wait.OK:
            return Abort("takeoff-failed", f"take-off to {alt:g} m did not finish within "
                         f"{self.cfg.takeoff_timeout_s:g} s (mode {st.mode})")  # fmt: skip
        self.say(f"take-off complete at t = {st.t:.2f} s")
        return None

    # ------------------------------------------------------------------ search
    async def _search(self) -> Abort | None:
        st, res, p = self.v.state, self.result, self.params
        dt = 1.0 / p.rate_hz
        t_air = st.t
        t_next = st.t
        searching = False
        offboard = False
        t_off0, n0 = math.nan, 0
        t_ask, t_first_ask = -math.inf, math.nan  # offboard requests: the next allowed, the first made
        path, prev = 0.0, None
        chem_seen = -1  # the first tick sees the newest reading as new: the strategy has not seen it
        while True:
            got = await self.v.next_tick(t_next)
            if got == Wait.LINK_LOST:
                return Abort("link-lost", self.v.link_lost() or "link lost")
            if got == Wait.TIMEOUT:
                continue  # no fresh state yet: the checks below need one
            t = st.t
            if t - t_next >= dt - 1e-9:  # behind (late or bunched telemetry): skip ticks, never queue them
                res.ticks_skipped += int((t - t_next) / dt)
            t_next = max(t_next + dt, t - 0.5 * dt)
            chem_new, chem_seen = st.chem_seq != chem_seen, st.chem_seq
            self._wind_info = self.wind.info(t)
            abort = self._checks(t, offboard, t_off0)
            if abort is not None:
                return abort
            if not searching:
                wind = self._wind_info
                waiting = wind is not None and not math.isfinite(wind.upwind_rad)
                if waiting and t - t_air < p.wind_wait_s:
                    continue
                if waiting and self.wind.mode == "estimated" and not self.wind.ready():
                    return Abort("estimator-fault", f"the wind estimator never started: {self.wind.missing()}")
                searching = True
                self.say(f"no usable wind direction after {p.wind_wait_s:g} s: searching without it" if waiting
                         else f"wind direction usable at t = {t:.2f} s: starting the search")  # fmt: skip
            if st.pos is not None:
                if prev is not None:
                    path += float(np.hypot(*(st.pos[0:2] - prev[0:2])))
                prev = st.pos.copy()
            if self.on_tick is not None:
                self.on_tick(t)
            if st.obs_pos is None:
                continue
            sp = self._strategy_tick(t, chem_new, path)
            self._send(sp)
            if not offboard and t >= t_ask:
                try:  # PX4 wants the setpoint stream before the mode switch: one was just sent
                    await self.v.start_offboard()
                except CommandError as e:
                    # On a lossy link the setpoints may not have arrived yet: MAVSDK repeats the last one
                    # at 20 Hz, so ask again every 0.5 s, for OFFBOARD_RETRY_S at most.
                    t_first_ask = t if math.isnan(t_first_ask) else t_first_ask
                    if t - t_first_ask >= OFFBOARD_RETRY_S:
                        return Abort("offboard-rejected", f"the autopilot rejected offboard control for "
                                     f"{t - t_first_ask:.1f} s: {e}")  # fmt: skip
                    t_ask = t + 0.5
                    continue
                offboard, t_off0, n0 = True, t, res.setpoints
            if t > t_off0:
                res.setpoint_rate_hz = round((res.setpoints - n0) / (t - t_off0), 2)
                res.tick_rate_hz = round(res.ticks / (t - t_off0), 2)
            if sp.done:
                if res.declared_ned is None:
                    return Abort("search-ended", f"the strategy ended without a declaration (state {sp.state})")
                return None

    def _checks(self, t: float, offboard: bool, t_off0: float) -> Abort | None:
        st, sup = self.v.state, self.sup
        assert sup is not None
        if st.crashed:
            return Abort("crash", "the vehicle crashed")
        abort = sup.check_time(t - self.t_arm)
        if abort is None and st.pos is not None:
            abort = sup.check_vehicle(st.pos)
        if abort is None:
            abort = self.wind.fault(t)
        if abort is None and not st.armed:
            abort = Abort("landed", f"the vehicle disarmed during the search (mode {st.mode})")
        # The mode is the last HEARTBEAT's (1 Hz): only one that showed OFFBOARD after the switch makes a
        # later other mode a departure; heartbeats lost on a bad link are not one.
        self._offboard_seen = offboard and (self._offboard_seen or st.mode == "OFFBOARD")
        if abort is None and offboard and st.mode and st.mode != "OFFBOARD":
            if self._offboard_seen:
                abort = Abort("offboard-lost", f"the vehicle left offboard on its own (mode {st.mode})")
            elif t - t_off0 > OFFBOARD_CONFIRM_S:
                abort = Abort("offboard-lost", f"no heartbeat showed offboard within {OFFBOARD_CONFIRM_S:g} s of the "
                              f"accepted switch (mode {st.mode})")  # fmt: skip
        if abort is None and (why := self.v.link_lost()) is not None:
            abort = Abort("link-lost", why)
        return abort

    def _strategy_tick(self, t: float, chem_new: bool, path: float) -> Setpoint:
        st, res = self.v.state, self.result
        assert st.obs_pos is not None
        obs = Observation(t=t, position_ned=st.obs_pos.copy(), velocity_ned=st.obs_vel.copy(), chem_mg_m3=st.chem,
                          detected=st.chem > 0.0, chem_new=chem_new, wind=self._wind_info,
                          chem_t=st.chem_t)  # fmt: skip
        sp = self.strategy.update(obs)
        res.ticks += 1
        for line in getattr(self.strategy, "pop_messages", list)():
            self.say(f"strategy: {line}")
        if sp.declared_source_ned is not None and res.declared_ned is None:
            res.declared_ned = [round(float(v), 3) for v in sp.declared_source_ned]
            res.confidence = round(float(sp.confidence), 3)
            res.credible_radius_m = float(getattr(sp, "credible_radius_m", math.nan))
            self.t_declared = float(sp.info.get("t_declared", t))
            res.time_s = round(self.t_declared - self.t_arm, 2)
            res.path_m = round(path, 2)
            # One clock: t is vehicle time, as in every other line and in the recording.
            self.say(f"source declared at N {res.declared_ned[0]:.1f} E {res.declared_ned[1]:.1f} m "
                     f"(confidence {res.confidence:.2f}) at t = {self.t_declared:.1f} s, "
                     f"{res.time_s:.1f} s after arming")  # fmt: skip
        if res.declared_ned is None:
            res.path_m = round(path, 2)
        res.state = sp.state
        out: list[tuple[str, str]] = []
        if sp.state and sp.state != self._published:
            self._published = sp.state
            out.append(state_fields(sp.state))
        if res.declared_ned is not None and not self._declared_sent:
            self._declared_sent = True
            out += declaration_fields(t, res.declared_ned, res.confidence)
        if out:
            self.v.publish(out)
        return sp

    def _send(self, sp: Setpoint) -> None:
        st, sup = self.v.state, self.sup
        assert sup is not None
        pos, vel = sp.position_ned, sp.velocity_ned
        if pos is None and vel is None:
            pos = None if st.pos is None else st.pos.copy()
        pos, vel = sup.clamp(pos, vel, st.pos, st.vel)
        self.result.clamped_setpoints = sup.clamped
        self.v.send_setpoint(pos, vel, sp.yaw_rad)
        self.result.setpoints += 1

    # ------------------------------------------------------------------ endings
    async def _land_at_declared(self) -> None:
        """Fly over the declared source (offboard, at the current height), land there, wait for the disarm."""
        st, res = self.v.state, self.result
        assert res.declared_ned is not None and st.pos is not None and self.sup is not None
        target = np.array(res.declared_ned, dtype=float)
        target[2] = st.pos[2]

        def over() -> bool:
            return (st.pos is not None and float(np.hypot(*(st.pos[0:2] - target[0:2]))) < 0.5
                    and float(np.linalg.norm(st.vel)) < 0.5)  # fmt: skip

        t_end = st.t + 20.0
        t_next = st.t
        while not over() and st.t < t_end:
            pos, _ = self.sup.clamp(target, None, st.pos, st.vel)
            self.v.send_setpoint(pos, None, None)
            t_next = max(t_next + 0.1, st.t)
            if await self.v.next_tick(t_next) == Wait.LINK_LOST:
                await self._abort(Abort("link-lost", self.v.link_lost() or "link lost over the declaration"))
                return
        res.cause = "declared"
        self.say("over the declared source: landing")
        await self._land(hold_first=False)

    async def _abort(self, abort: Abort) -> None:
        """Say why, then hold and land (or, on a link loss, wait for the link and look again)."""
        self.result.cause = abort.cause
        self.say(abort.line())
        if abort.cause == "link-lost":
            await self._after_link_loss()
            return
        await self._land(hold_first=True)

    async def _after_link_loss(self) -> None:
        self.result.link_lost = True
        boots = self.v.state.boots
        await self._quietly(self.v.stop_offboard())  # stop MAVSDK repeating the last setpoint
        if not await self.v.await_link(self.cfg.link_grace_s):
            self.say(f"LINK: still down after {self.cfg.link_grace_s:g} s: the autopilot's failsafe is in charge "
                     f"({self._last_seen()})")  # fmt: skip
            return
        st = self.v.state
        self.say(f"LINK: telemetry is back (mode {st.mode}, {'armed' if st.armed else 'disarmed'})")
        if not st.armed and st.boots > boots:
            # A restarted autopilot (PX4 killed and started again) boots disarmed: whatever brought the
            # vehicle down while it was gone was not its failsafe (in windseek's HIL: windseek's safety landing).
            self.say("LINK: the autopilot restarted while the link was down (its clock went back) and is disarmed: "
                     "not its failsafe's landing; the vehicle was brought down outside the autopilot (in windseek's "
                     f"simulation, by windseek's safety landing) ({self._last_seen()})")  # fmt: skip
            return
        if not st.armed:
            self.say("LINK: the vehicle already landed and disarmed (autopilot failsafe)")
            return
        await self._land(hold_first=st.mode not in ("AUTO.LAND", "AUTO.RTL"))

    async def _land(self, hold_first: bool) -> None:
        st, cfg = self.v.state, self.cfg
        if not st.armed:
            self.say(f"the vehicle is already disarmed (mode {st.mode})")
            return
        try:
            if hold_first:
                await self._quietly(self.v.stop_offboard())
                if st.mode not in ("AUTO.LOITER", "AUTO.LAND"):
                    await self.v.hold()
                self.say(f"holding for {cfg.hold_s:g} s, then landing")
                await self.v.wait(lambda: not st.armed, cfg.hold_s)
            if st.armed and st.mode != "AUTO.LAND":
                await self.v.land()
        except CommandError as e:  # report and keep watching: the autopilot may still land
            self.say(f"SAFETY: land command failed ({e}); waiting for the autopilot")
        await self._wait_disarm()

    async def _wait_disarm(self) -> None:
        st, cfg = self.v.state, self.cfg
        got = await self.v.wait(lambda: not st.armed, cfg.land_timeout_s)
        if got == Wait.LINK_LOST:
            self.result.link_lost = True
            self.say(f"LINK: lost while landing (mode {st.mode}); waiting up to {cfg.link_grace_s:g} s for it")
            if not await self.v.await_link(cfg.link_grace_s):
                self.say(f"LINK: still down: the autopilot's failsafe is in charge ({self._last_seen()})")
                return
            if st.armed:
                got = await self.v.wait(lambda: not st.armed, cfg.land_timeout_s)
        if not st.armed:
            self.say("landed and disarmed")
        elif got == Wait.LINK_LOST:
            self.say(f"LINK: lost again while landing (mode {st.mode})")
        else:
            self.say(f"not disarmed within {cfg.land_timeout_s:g} s (mode {st.mode})")

    @staticmethod
    async def _quietly(coro: Any) -> None:
        with contextlib.suppress(CommandError):
            await coro

    def _last_seen(self) -> str:
        st, home = self.v.state, self.result.home_ned
        alt = "" if st.pos is None or home is None else f", {home[2] - float(st.pos[2]):.1f} m above home"
        return f"last seen: mode {st.mode}, {'armed' if st.armed else 'disarmed'}{alt}"

    def _final(self) -> None:
        st, res = self.v.state, self.result
        if self.v.link_lost() is None:
            res.disarmed = not st.armed
            res.landed = st.landed == LANDED_ON_GROUND or not st.armed
        else:  # the mission ends with the link down: how the vehicle is now is not known (None)
            res.disarmed = res.landed = None
        res.final_ned = None if st.pos is None else [round(float(v), 3) for v in st.pos]
        if math.isfinite(st.t) and math.isfinite(self.t_arm):
            res.mission_time_s = round(st.t - self.t_arm, 2)
        t_arm = self.t_arm if math.isfinite(self.t_arm) else 0.0
        res.verifications = [
            {"t_start_s": round(v.t_start - t_arm, 2), "duration_s": round(v.end(st.t) - v.t_start, 2),
             "outcome": v.outcome, "candidate_ne": [round(c, 3) for c in v.candidate_ne]}
            for v in getattr(self.strategy, "verifications", [])]  # fmt: skip
        wi = self._wind_info
        if wi is not None and self.wind.ready():
            res.wind_ned = [round(float(v), 3) for v in wi.wind_ned]
        res.estimator = self.wind.report()
