"""The identification manoeuvre flown on any PX4 through MAVLink (PX4 SIH, PX4 SITL with windseek as its
simulator, a real vehicle), with MAVSDK (``mavsdk.asyncio``, 4.x) as the mission runner does.

The flight, each step bounded in time:

1. connect (:class:`mission.runners.mavsdk_vehicle.MavsdkVehicle`: the autopilot's HEARTBEAT, health,
   position); ask for the streams the estimation needs (SET_MESSAGE_INTERVAL: HIGHRES_IMU or SCALED_IMU,
   ATTITUDE_QUATERNION, LOCAL_POSITION_NED, ACTUATOR_OUTPUT_STATUS, SERVO_OUTPUT_RAW, ESC_STATUS when asked for),
   measure what arrives over two seconds and say it (the other IMU message and ATTITUDE are asked for when the
   first is missing); refuse to fly without IMU, attitude, velocity and motor outputs, and when the autopilot's
   clock runs faster than ``max_clock_speed`` times the wall clock (a simulator in lockstep as fast as it can:
   the setpoints go at wall-clock rates through MAVSDK, so at 8x real time a 50 Hz setpoint reaches the vehicle
   every 0.16 s of its time and the 3 Hz end of the multisine is not flown);
2. read THR_MDL_FAC (the motor map: rotor speed = w_max sqrt(thrust), thrust = f u^2 + (1 - f) u) and
   MPC_THR_HOVER; set and read back the link-loss failsafes (:func:`identify.fly.px4_link.link_loss_failsafe`);
   refuse to fly when the data-link-loss action is not on;
3. arm, take off to ``altitude_m``, hold ``settle_s`` (the hover collective thrust is measured from the
   outputs), then offboard: the fitting manoeuvre and then the validation manoeuvre in the same flight, both
   from the point where the first started (the reference's path ends where it began), as attitude and
   collective-thrust setpoints at 50 Hz of vehicle time (:mod:`identify.fly.px4_setpoint`);
   (the take-off altitude goes in the command: :func:`mission.runners.takeoff.takeoff_above_home`);
4. hold, land, wait for the disarm; restore the failsafe parameters it changed.

Safety (:mod:`identify.fly.px4_guard`) at every setpoint: the geofence box and altitude band, the tilt, the
motor saturation, the link and offboard mode. An abort is said in one line (``ABORT (cause): why``), PX4 is
switched to HOLD, then LAND, and the abort is in the result; a lost link leaves the vehicle to PX4's
failsafes (set in step 2) and the flight waits ``link_grace_s`` for the link to come back.

What is recorded and how it becomes :class:`~identify.flight_data.FlightData`: :mod:`identify.fly.px4_record`.
Units SI; NED (the autopilot's local frame), FRD body; vehicle time = the autopilot's boot clock.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimator.motor_output import OutputMap
from identify.design import Manoeuvre, ManoeuvreSpec, design
from identify.flight_data import FlightData
from identify.fly.px4_guard import Guard, GuardLimits
from identify.fly.px4_link import Params, link_loss_failsafe, request_streams
from identify.fly.px4_record import MESSAGES, Recorder
from identify.fly.px4_setpoint import AttitudeSetpoint, ManoeuvreLaw, ReferenceFit, fit_reference
from mission.result import MissionError
from mission.runners.mavsdk_vehicle import LinkConfig, MavsdkVehicle
from mission.runners.takeoff import takeoff_above_home
from mission.safety import Abort
from mission.vehicle import CommandError, Wait
from vehicle.params import VehicleParams

#: Streams asked for (Hz of vehicle time); the IMU rate is the config's.
STREAMS = {"ATTITUDE_QUATERNION": 100.0, "LOCAL_POSITION_NED": 50.0, "ACTUATOR_OUTPUT_STATUS": 100.0,
           "SERVO_OUTPUT_RAW": 50.0, "ESC_STATUS": 50.0, "EXTENDED_SYS_STATE": 5.0}  # fmt: skip
#: Setpoint period, s of vehicle time.
TICK_S = 0.02
LANDED_IN_AIR = 2


@dataclass
class Px4FlightConfig:
    """One identification flight. ``fitting`` / ``validation``: the manoeuvres, whose ``amplitudes`` are
    (thrust fraction of hover, roll, pitch, yaw in rad) on PX4 (:mod:`identify.fly.px4_setpoint`); None
    validation: the fitting manoeuvre only. Times are vehicle seconds unless named wall."""

    connect: str
    vehicle: VehicleParams
    fitting: ManoeuvreSpec
    validation: ManoeuvreSpec | None = None
    altitude_m: float = 10.0
    limits: GuardLimits = field(default_factory=GuardLimits)
    speed_hint: float = 1.0  # the simulator's speed factor (PX4_SIM_SPEED_FACTOR): scales the loss timeouts
    output_range: tuple[float, float] = (1000.0, 2000.0)
    esc_component: int | None = None
    esc_order: str = "px4"  # ESC_STATUS numbering: px4 (ESC i = PX4 output i) or rotors (the file's rotor i)
    max_clock_speed: float | None = 6.0  # refuse / abort beyond this autopilot clock over wall clock; None: no check
    imu: str = "HIGHRES_IMU"  # or SCALED_IMU (identify.fly.px4_record.IMU_MESSAGES)
    imu_rate_hz: float = 250.0
    settle_s: float = 5.0
    dl_loss_s: float = 5.0  # wall seconds
    of_loss_s: float = 1.0  # wall seconds
    restore_params: bool = True
    connect_timeout_s: float = 30.0  # wall
    health_timeout_s: float = 60.0  # wall
    takeoff_timeout_s: float = 60.0
    land_timeout_s: float = 120.0
    hold_s: float = 2.0
    link_grace_s: float = 30.0  # wall
    say: Callable[[str], None] = print
    stop: Callable[[], bool] = lambda: False  # polled: True = stop now (Ctrl-C), abort and land


@dataclass
class Px4FlightResult:
    """The flight: the manoeuvres' records (None when not flown to the end), the abort (None: none) and
    everything said in numbers (``report``, JSON-safe)."""

    fitting: FlightData | None = None
    validation: FlightData | None = None
    abort: Abort | None = None
    report: dict[str, Any] = field(default_factory=dict)


def vehicle_output_map(vehicle: VehicleParams, raw_range: tuple[float, float], thr_mdl_fac: float | None
                       ) -> OutputMap:  # fmt: skip
    """PX4 output -> rotor of the vehicle file (``px4_outputs``), the PWM range, the vehicle's rotor speeds."""
    return OutputMap.for_vehicle(vehicle, "px4", thr_mdl_fac, raw_range)


async def fly_px4(cfg: Px4FlightConfig) -> Px4FlightResult:
    """Fly the flight of the module docstring. MissionError (one line) when it cannot start or refuses to."""
    cfg.limits.validate()
    if not cfg.limits.floor_m + 5.0 <= cfg.altitude_m <= cfg.limits.ceiling_m - 5.0:
        raise MissionError(f"altitude {cfg.altitude_m:g} m: needs 5 m of room to the floor {cfg.limits.floor_m:g} m "
                           f"and the ceiling {cfg.limits.ceiling_m:g} m")  # fmt: skip
    rec = Recorder(vehicle_output_map(cfg.vehicle, cfg.output_range, None), cfg.vehicle.n_rotors, cfg.esc_component,
                   cfg.imu, cfg.esc_order)  # fmt: skip
    link = LinkConfig(cfg.connect, cfg.connect_timeout_s, cfg.health_timeout_s, cfg.limits.link_timeout_s,
                      cfg.speed_hint)  # fmt: skip
    res = Px4FlightResult()
    async with MavsdkVehicle(link, cfg.say, rec.sink, MESSAGES) as v:
        rec.target = v.target
        flight = _Flight(cfg, v, rec, res)
        await flight.prepare()
        try:
            await flight.fly()
        finally:
            await flight.restore()
    return res


class _Flight:
    """The steps of :func:`fly_px4` on one connected vehicle."""

    def __init__(self, cfg: Px4FlightConfig, v: MavsdkVehicle, rec: Recorder, res: Px4FlightResult) -> None:
        self.cfg, self.v, self.rec, self.res = cfg, v, rec, res
        self.params = Params(v.param, timeout_s=10.0)
        self.before: dict[str, float] = {}
        self.changed: dict[str, float] = {}
        self.rep = res.report
        self.clock_max = 0.0  # the fastest 5-s window of the autopilot's clock in the manoeuvres (x wall)

    def say(self, line: str) -> None:
        self.cfg.say(f"identify: {line}")

    # ------------------------------------------------------------------ before take-off
    async def prepare(self) -> None:
        cfg, v, rec = self.cfg, self.v, self.rec
        assert v.target is not None
        if v.state.armed or v.state.landed == LANDED_IN_AIR:  # before any parameter is touched
            raise MissionError("the vehicle is already armed or flying: start on the ground, disarmed")
        wanted = {cfg.imu: cfg.imu_rate_hz, **STREAMS}
        if cfg.esc_component is None:
            wanted.pop("ESC_STATUS")
        answers = await request_streams(v.direct, v.target, wanted)
        t0, w0 = v.state.t, time.monotonic()
        await v.wait(lambda: v.state.t - t0 >= 2.0, math.inf, 2.0 + 4.0 / max(cfg.speed_hint, 0.1))
        rates = rec.rates_hz(t0, v.state.t)
        clock = (v.state.t - t0) / max(time.monotonic() - w0, 1e-3)
        if rates[cfg.imu] == 0.0:
            other = "SCALED_IMU" if cfg.imu == "HIGHRES_IMU" else "HIGHRES_IMU"
            answers.update(await request_streams(v.direct, v.target, {other: cfg.imu_rate_hz, "ATTITUDE": 100.0}))
            t0 = v.state.t
            await v.wait(lambda: v.state.t - t0 >= 2.0, math.inf, 2.0 + 4.0 / max(cfg.speed_hint, 0.1))
            rates = rec.rates_hz(t0, v.state.t)
        seen = {k: round(r, 1) for k, r in rates.items() if r > 0}
        missing = sorted(k for k in wanted if rates.get(k, 0.0) == 0.0 and k != "EXTENDED_SYS_STATE")
        self.rep["streams"] = {"requested": wanted, "answers": answers, "rates_hz": seen, "missing": missing}
        self.say("streams: " + ", ".join(f"{k} {r:g} Hz" for k, r in seen.items()) +
                 (f"; missing: {', '.join(missing)}" if missing else ""))  # fmt: skip
        if rec.ignored_esc and cfg.esc_component is None:
            self.say("ESC_STATUS from the autopilot is not used (PX4 SITL's is a placeholder, rpm = 6000 x output): "
                     "--esc-component names a real ESC telemetry source")  # fmt: skip
        need = {"IMU": ("HIGHRES_IMU", "SCALED_IMU"), "attitude": ("ATTITUDE_QUATERNION", "ATTITUDE"),
                "velocity": ("LOCAL_POSITION_NED",), "motor outputs": ("ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW")}
        lacking = [k for k, names in need.items() if not any(n in seen for n in names)]
        if lacking:
            raise MissionError(f"refusing to fly: no {', '.join(lacking)} stream from the autopilot (asked with "
                               "SET_MESSAGE_INTERVAL; the answers are in the streams line)")  # fmt: skip
        self.rep["clock_speed"] = round(clock, 2)
        self.say(f"the autopilot's clock runs at {clock:.2f}x the wall clock")
        if cfg.max_clock_speed is not None and clock > cfg.max_clock_speed:
            raise MissionError(f"refusing to fly: the autopilot's clock runs at {clock:.1f}x real time, above "
                               f"{cfg.max_clock_speed:g}x: the setpoints and streams are paced by the wall clock, too "
                               "coarse for the manoeuvre at that speed; pace the simulator (windseek sitl --px4 "
                               "--speed K, PX4_SIM_SPEED_FACTOR) or raise --max-clock-speed")  # fmt: skip
        fac = await self.params.get("THR_MDL_FAC", "float")
        hover = await self.params.get("MPC_THR_HOVER", "float")
        rec.outputs = vehicle_output_map(cfg.vehicle, cfg.output_range, fac)
        self.rep["thr_mdl_fac"], self.rep["mpc_thr_hover"] = fac, hover
        self.say(f"THR_MDL_FAC = {fac}: rotor speed = {cfg.vehicle.rotor_speed_max_rad_s:g} rad/s x sqrt(thrust)"
                 if fac is not None else "no THR_MDL_FAC: rotor speed taken as linear in the output")  # fmt: skip
        now, before, problems = await link_loss_failsafe(self.params, cfg.speed_hint, cfg.dl_loss_s, cfg.of_loss_s)
        self.before = before
        self.changed = {k: val for k, val in now.items() if k in before and not math.isclose(val, before[k])}
        self.rep["failsafe"] = {"now": now, "before": before, "problems": problems}
        for p in problems:
            self.say(f"SAFETY: {p}")
        self.say("failsafes read back: " + ", ".join(f"{k} {val:g}" + (f" (was {before[k]:g})" if k in self.changed
                                                                      else "") for k, val in now.items()))  # fmt: skip
        if now.get("NAV_DLL_ACT", 0.0) == 0.0:
            raise MissionError("refusing to fly: the data-link-loss failsafe (NAV_DLL_ACT) is not on and could not "
                               "be set")  # fmt: skip

    async def restore(self) -> None:
        """Put back the failsafe values this flight changed (on the ground only)."""
        if not self.cfg.restore_params or not self.changed or self.v.state.armed or self.v.link_lost():
            return
        put = []
        for name in self.changed:
            with contextlib.suppress(RuntimeError):
                await self.params.set(name, self.before[name])
                put.append(f"{name} {self.before[name]:g}")
        self.say("restored " + (", ".join(put) if put else "nothing (the autopilot did not take the old values)"))

    # ------------------------------------------------------------------ the flight
    async def fly(self) -> None:
        cfg, v, st = self.cfg, self.v, self.v.state
        assert st.pos is not None
        home = st.pos.copy()
        self.guard = Guard(cfg.limits, home)
        self._design()  # before the take-off: the phase optimization takes seconds
        if cfg.stop():
            raise MissionError("stopped by the user before the take-off")
        try:
            await v.arm()
        except CommandError as e:
            raise MissionError(str(e)) from None
        self.say(f"armed at t = {st.t:.2f} s; taking off to {cfg.altitude_m:g} m")
        why = await takeoff_above_home(v, cfg.altitude_m)
        abort = Abort("command-failed", why) if why is not None else await self._take_off(home)
        if abort is None:
            abort = await self._manoeuvres(home)
        self.res.abort = abort
        if abort is not None:
            self.say(abort.line())
        await self._land(abort)
        if self.clock_max > 0.0:
            self.rep["clock_speed_max"] = round(self.clock_max, 2)
        self.rep.update({"max_tilt_deg": round(self.guard.max_tilt_deg, 2),
                         "max_saturated_s": round(self.guard.max_saturated_s, 3),
                         "disarmed": None if v.link_lost() else not st.armed})  # fmt: skip

    async def _take_off(self, home: np.ndarray) -> Abort | None:
        cfg, v, st = self.cfg, self.v, self.v.state

        def up() -> bool:
            return st.pos is not None and st.mode == "AUTO.LOITER" and -(st.pos[2] - home[2]) > cfg.altitude_m - 0.7

        got = await v.wait(lambda: up() or cfg.stop(), cfg.takeoff_timeout_s)
        if cfg.stop():
            return Abort("interrupted", "stopped by the user during the take-off")
        if got == Wait.LINK_LOST:
            return Abort("link-lost", v.link_lost() or "link lost during the take-off")
        if got != Wait.OK:
            return Abort("command-failed", f"take-off to {cfg.altitude_m:g} m did not finish within "
                         f"{cfg.takeoff_timeout_s:g} s (mode {st.mode})")  # fmt: skip
        self.say(f"take-off complete at t = {st.t:.2f} s; holding {cfg.settle_s:g} s")
        self.rep["takeoff_t_s"] = round(st.t, 3)
        t0 = st.t
        await v.wait(lambda: st.t - t0 >= cfg.settle_s or cfg.stop(), cfg.settle_s + 1.0)
        if cfg.stop():
            return Abort("interrupted", "stopped by the user in the hover")
        return self.guard.position(st.pos, False) if st.pos is not None else None

    def _design(self) -> None:
        """The manoeuvres (unit-scale multisines: thrust fraction and angles in rad) and their reference fits at
        the take-off altitude."""
        cfg = self.cfg
        specs = [("fitting", cfg.fitting)] + ([("validation", cfg.validation)] if cfg.validation else [])
        self.designs: list[tuple[str, Manoeuvre, ReferenceFit]] = []
        for name, spec in specs:
            m = design(spec, 1.0)
            fit = fit_reference(m, cfg.limits.fence_m, cfg.altitude_m, cfg.limits.floor_m, cfg.limits.ceiling_m)
            self.say(f"{name} manoeuvre: {spec.hover_s:g} s hover + {spec.duration_s:g} s; {fit.note}")
            self.designs.append((name, m, fit))

    def _hover_thrust(self, t0: float, t1: float) -> float:
        """Mean collective thrust (normalized) of the motor outputs between t0 and t1 (PX4's thrust model)."""
        rows = [r for t, r in self.rec.snapshot(self._outputs_name()) if t0 <= t <= t1]
        out = self.rec.outputs
        if not rows:
            return float(self.rep.get("mpc_thr_hover") or 0.5)
        u = np.clip((np.array(rows) - out.raw_min) / (out.raw_max - out.raw_min), 0.0, 1.0)
        f = out.thr_mdl_fac or 0.0
        return float(np.mean(f * u * u + (1.0 - f) * u))

    def _outputs_name(self) -> str:
        return "ACTUATOR_OUTPUT_STATUS" if self.rec.counts["ACTUATOR_OUTPUT_STATUS"] else "SERVO_OUTPUT_RAW"

    async def _manoeuvres(self, home: np.ndarray) -> Abort | None:
        cfg, v, st = self.cfg, self.v, self.v.state
        assert st.pos is not None
        hover = self._hover_thrust(st.t - min(cfg.settle_s, 3.0), st.t)
        self.rep["hover_thrust"] = round(hover, 4)
        self.say(f"hover collective thrust {hover:.3f} (MPC_THR_HOVER {self.rep.get('mpc_thr_hover')})")
        start, yaw0 = st.pos.copy(), st.yaw
        laws = [(name, ManoeuvreLaw(m, start, yaw0, hover, fit)) for name, m, fit in self.designs]
        self.rep["manoeuvres"] = {}
        sp = laws[0][1].setpoint(0.0, st.pos, st.vel)
        try:
            self._send(sp)
            await v.start_offboard()
        except CommandError as e:
            return Abort("command-failed", f"offboard refused: {e}")
        if await v.wait(lambda: st.mode == "OFFBOARD", 5.0) != Wait.OK:  # the HEARTBEAT that shows it
            return Abort("offboard-lost", f"PX4 accepted offboard but did not switch to it (mode {st.mode})")
        self.say(f"offboard at t = {st.t:.2f} s")
        for name, law in laws:
            t0 = st.t
            abort = await self._fly_one(law, t0)
            t1 = min(st.t, t0 + law.m.total_s)
            self.rep["manoeuvres"][name] = {"t0_s": round(t0, 3), "t1_s": round(t1, 3), "completed": abort is None}
            if abort is not None:
                return abort
            src = (f"PX4 over MAVLink ({cfg.connect}), {name} manoeuvre seed {law.m.spec.seed}, t = {t0:.1f}-"
                   f"{t1:.1f} s of the autopilot's clock")  # fmt: skip
            try:
                setattr(self.res, name, self.rec.flight_data(t0, t1, src))
            except ValueError as e:
                self.say(f"{name} manoeuvre not usable: {e}")
            self.say(f"{name} manoeuvre done at t = {st.t:.2f} s")
        return None

    def _send(self, sp: AttitudeSetpoint) -> None:
        from mavsdk.plugins.offboard import Attitude

        try:
            self.v.offb._plugin.set_attitude(Attitude(math.degrees(sp.roll_rad), math.degrees(sp.pitch_rad),
                                                      math.degrees(sp.yaw_rad), sp.thrust))  # fmt: skip
        except Exception as e:  # noqa: BLE001 - OffboardError or a closed link
            raise CommandError(f"attitude setpoint: {e}") from None

    async def _fly_one(self, law: ManoeuvreLaw, t0: float) -> Abort | None:
        cfg, v, st, guard = self.cfg, self.v, self.v.state, self.guard
        t_next = t0
        wall_limit = 30.0 + 3.0 * law.m.total_s / max(cfg.speed_hint, 0.1)
        wall_end = time.monotonic() + wall_limit
        clock0 = (time.monotonic(), st.t)  # the autopilot's clock against the wall clock, windows of 5 s of wall
        while True:
            got = await v.next_tick(t_next)
            if got == Wait.LINK_LOST:
                return Abort("link-lost", v.link_lost() or "link lost")
            if cfg.stop():
                return Abort("interrupted", "stopped by the user")
            if time.monotonic() > wall_end:
                return Abort("stalled", f"the manoeuvre did not end within {wall_limit:.0f} s of wall time (the "
                             f"autopilot's clock at {st.t - t0:.1f} of {law.m.total_s:g} s)")
            if got == Wait.TIMEOUT:
                continue
            if (wall := time.monotonic()) - clock0[0] >= 5.0:
                clock = (st.t - clock0[1]) / (wall - clock0[0])
                self.clock_max = max(self.clock_max, clock)
                clock0 = (wall, st.t)
                if cfg.max_clock_speed is not None and clock > cfg.max_clock_speed:
                    return Abort("clock-speed", f"the autopilot's clock ran at {clock:.1f}x real time for 5 s, "
                                 f"above {cfg.max_clock_speed:g}x: the setpoints are too coarse at that speed")
            tau = st.t - t0
            if tau >= law.m.total_s:
                return None
            t_next = max(t_next + TICK_S, st.t - 0.5 * TICK_S)
            if st.mode != "OFFBOARD":
                return Abort("offboard-lost", f"the autopilot left offboard (mode {st.mode})")
            assert st.pos is not None
            out = self.rec.outputs_u
            abort = (guard.position(st.pos, True) or guard.attitude(self.rec.tilt_rad())
                     or (guard.outputs(*out) if out is not None else None))  # fmt: skip
            if abort is not None:
                return abort
            try:
                self._send(law.setpoint(tau, st.pos, st.vel))
            except CommandError as e:
                return Abort("command-failed", str(e))

    async def _land(self, abort: Abort | None) -> None:
        cfg, v, st = self.cfg, self.v, self.v.state
        if abort is not None and abort.cause == "link-lost":
            with contextlib.suppress(CommandError):
                await v.stop_offboard()
            if not await v.await_link(cfg.link_grace_s):
                self.say(f"LINK: still down after {cfg.link_grace_s:g} s: PX4's failsafe is in charge")
                return
            self.say(f"LINK: telemetry is back (mode {st.mode}, {'armed' if st.armed else 'disarmed'})")
        if not st.armed:
            self.say(f"the vehicle is already disarmed (mode {st.mode})")
            return
        try:
            if st.mode == "OFFBOARD":
                with contextlib.suppress(CommandError):
                    await v.stop_offboard()  # MAVSDK stops repeating the last setpoint
            if st.mode not in ("AUTO.LOITER", "AUTO.LAND", "AUTO.RTL"):
                await v.hold()
            self.say(f"holding for {cfg.hold_s:g} s, then landing")
            await v.wait(lambda: not st.armed, cfg.hold_s)
            if st.armed and st.mode != "AUTO.LAND":
                await v.land()
        except CommandError as e:
            self.say(f"SAFETY: hold / land failed ({e}); waiting for the autopilot")
        got = await v.wait(lambda: not st.armed, cfg.land_timeout_s)
        self.say("landed and disarmed" if got == Wait.OK else f"not disarmed within {cfg.land_timeout_s:g} s "
                 f"(mode {st.mode}, {got.value})")  # fmt: skip
