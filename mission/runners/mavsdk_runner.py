"""MAVSDK runner: the same strategy objects as the in-process runner, flown through an autopilot.

``await run_mission(MissionConfig(...))`` (or ``windseek mission --connect URL --strategy NAME``)
connects with MAVSDK (``mavsdk.asyncio``, 4.x) over UDP, TCP or serial, waits for health, arms,
takes off to the search altitude, waits (hovering) for a usable wind direction, enters offboard
and runs the strategy at its tick rate (10 Hz of *vehicle* time, so the loop follows the
autopilot's clock at any simulator speed factor; MAVSDK also repeats the last setpoint at
20 Hz), then flies over the declared source, lands there and waits for the disarm.

One link carries everything (one process can own a serial port): the estimator's inputs and the
chemical reading come through MAVSDK's ``mavlink_direct`` plugin as JSON fields and are handed to
:class:`~estimator.mavlink_adapter.MavlinkWindAdapter` as pymavlink-like objects:

- IMU: HIL_SENSOR (every sample of the project's SITL) or HIGHRES_IMU (PX4), the first seen wins;
- attitude: ATTITUDE_QUATERNION; velocity and position: LOCAL_POSITION_NED (m, m/s, NED);
- rotor speeds: ESC_STATUS (rpm); chemical reading: NAMED_VALUE_FLOAT ``CHEM`` (mg/m^3, 0 below
  the sensor's detection limit, so ``detected`` = reading > 0);
- mode, armed and landed state: HEARTBEAT (PX4 custom modes), EXTENDED_SYS_STATE; the
  autopilot's STATUSTEXT lines are echoed.

What the runner publishes (:mod:`wire.names`, through ``mavlink_direct``, from the
MAVSDK ground-station identity): the strategy state on every change as STATUSTEXT ``state: NAME``,
and the declaration once as NAMED_VALUE_FLOAT ``SRC_N``, ``SRC_E``, ``SRC_D`` (m, NED, local
frame), then ``SRC_CONF`` (0..1). ``windseek sitl --rrd/--exit-summary`` and any tlog record them.

Wind modes: ``estimated`` (the UKF run live on those messages from lift-off: paused while
EXTENDED_SYS_STATE says ON_GROUND; default), ``mavlink`` (WIND_COV
from the autopilot, e.g. PX4's own wind estimate or a relayed external ``windseek`` estimator),
``none`` (pure chemotaxis). There is no oracle over MAVLink.

Safety (:mod:`mission.safety`): every setpoint is clamped into the geofence box and altitude
band; the vehicle outside the box, the time limit, an estimator fault or an offboard rejection
stops the search with one ``ABORT (cause): why`` line, and the vehicle holds, then lands where it
is. A link loss (no telemetry for ``link_timeout_s`` wall seconds) leaves the vehicle to the
autopilot's failsafes (offboard loss: hold; data-link loss ``NAV_DLL_ACT``: land; the runner
makes sure NAV_DLL_ACT is set before take-off); if the link comes back the runner holds and lands.

Conventions: SI, NED (positions relative to the autopilot's local origin; altitudes above the
home point = the position at arming), yaw in rad inside (degrees on the MAVSDK API), wind =
air-mass velocity NED. Times: vehicle seconds (MAVLink time stamps) unless named ``wall``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimator.ground_gate import LANDED_IN_AIR, LANDED_ON_GROUND, GroundGate, withheld
from estimator.mavlink_adapter import MavlinkWindAdapter
from estimator.ukf import WindEstimator
from mission.runners.autopilot import find_autopilot
from mission.safety import Abort, EstimatorWatch, LinkWatchdog, SafetyLimits, Supervisor
from mission.strategies import make_strategy
from mission.strategies.base import Observation, WindInfo
from mission.strategies.params import CommonParams, load_params
from mission.wind_source import UpwindFilter
from wire import px4_modes
from wire.jsonsafe import json_safe
from wire.names import declaration_fields, publish, state_fields

WIND_MODES = ("estimated", "mavlink", "none")


DIRECT_MESSAGES = ("HIL_SENSOR", "HIGHRES_IMU", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "ESC_STATUS",
                   "NAMED_VALUE_FLOAT", "HEARTBEAT", "EXTENDED_SYS_STATE", "STATUSTEXT")  # fmt: skip
ESTIMATOR_MESSAGES = frozenset({"HIL_SENSOR", "HIGHRES_IMU", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED",
                                "ESC_STATUS"})  # fmt: skip


class MissionError(RuntimeError):
    """The mission could not start (no autopilot, not healthy, arming refused, ...)."""


@dataclass
class MissionConfig:
    """Everything one mission needs.

    connect: MAVSDK connection URL (``udpin://0.0.0.0:14540``, ``tcpout://host:5760``,
        ``serial:///dev/ttyUSB0:57600``, ...).
    strategy / params: strategy name and its parameters (None: the defaults); ``altitude_m``
        overrides ``params.altitude_m`` (search altitude above home, m).
    wind: ``estimated``, ``mavlink`` or ``none``.
    limits: geofence box, altitude band, time limit, link timeout.
    vehicle: vehicle file the estimator's force model uses (name or path).
    seed: seed of the strategy's randomized choices.
    connect_timeout_s / health_timeout_s: wall seconds to wait for a heartbeat / for health.
    takeoff_timeout_s, land_timeout_s: vehicle seconds for the take-off / the landing and disarm.
    hold_s: vehicle seconds to hold before landing after an abort.
    link_grace_s: wall seconds to wait for the link to come back after a loss.
    speed_hint: the simulator's speed factor, if known: wall-clock waits are divided by it.
    say: where the runner's lines go (default print).
    """

    connect: str
    strategy: str
    params: CommonParams | None = None
    altitude_m: float | None = None
    wind: str = "estimated"
    limits: SafetyLimits = field(default_factory=SafetyLimits)
    vehicle: str = "nasa_quad"
    seed: int = 0
    connect_timeout_s: float = 20.0
    health_timeout_s: float = 30.0
    takeoff_timeout_s: float = 40.0
    land_timeout_s: float = 90.0
    hold_s: float = 2.0
    link_grace_s: float = 30.0
    speed_hint: float = 1.0
    say: Callable[[str], None] = print


@dataclass
class MissionResult:
    """Summary of one mission (JSON-ready via :meth:`to_dict`).

    declared_ned: declared source (m, NED, autopilot local frame) or None; confidence 0..1.
    time_s: vehicle seconds from arming to the declaration (nan without one).
    path_m: horizontal path from the start of the search to the declaration (or the end), m.
    cause: ``declared`` or an abort cause of :data:`mission.safety.CAUSES`; reasons: the lines said.
    landed / disarmed: final state seen over the link; final_ned: last position (m, NED).
    verifications: the strategy's verification sweeps (see ``mission/README.md``), each a dict:
        ``t_start_s`` (vehicle s from arming), ``duration_s``, ``outcome`` (``verified``: found
        nothing, ``interrupted``: a hit, ``""``: still running at the end) and ``candidate_ne``
        (the candidate it tested, m, north / east in the autopilot's local frame).
    """

    strategy: str
    wind: str
    declared_ned: list[float] | None = None
    confidence: float = 0.0
    time_s: float = math.nan
    path_m: float = 0.0
    cause: str = ""
    reasons: list[str] = field(default_factory=list)
    landed: bool = False
    disarmed: bool = False
    final_ned: list[float] | None = None
    home_ned: list[float] | None = None
    mission_time_s: float = math.nan
    wall_s: float = 0.0
    setpoints: int = 0
    setpoint_rate_hz: float = math.nan
    ticks: int = 0
    tick_rate_hz: float = math.nan
    clamped_setpoints: int = 0
    state: str = ""
    wind_ned: list[float] | None = None
    estimator: dict[str, Any] = field(default_factory=dict)
    verifications: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        return json_safe(d)


class _Msg:
    """A pymavlink-like view of a mavlink_direct message: fields as attributes, ``get_type()``."""

    def __init__(self, mtype: str, fields: dict[str, Any]) -> None:
        self.__dict__.update(fields)
        self._mtype = mtype

    def get_type(self) -> str:
        return self._mtype



class VehicleState:
    """The latest telemetry (filled by the mavlink_direct handlers)."""

    def __init__(self) -> None:
        self.t = math.nan  # vehicle time of the newest stamped message, s
        self.pos: np.ndarray | None = None  # NED, m
        self.vel = np.zeros(3)  # NED, m/s
        self.yaw = 0.0  # rad
        self.armed = False
        self.mode = ""
        self.landed = 0  # MAV_LANDED_STATE
        self.chem = 0.0  # mg/m^3
        self.chem_seq = 0  # readings received
        self.wind_cov: tuple[float, np.ndarray, np.ndarray] | None = None  # (t, wind NED, cov)
        self.heartbeats = 0
        self.new_position = asyncio.Event()


class MavsdkMission:
    """One mission; see :func:`run_mission`."""

    def __init__(self, cfg: MissionConfig) -> None:
        if cfg.wind not in WIND_MODES:
            raise ValueError(f"wind mode {cfg.wind!r}: choose one of {', '.join(WIND_MODES)}")
        self.cfg = cfg
        self.params = cfg.params if cfg.params is not None else load_params(cfg.strategy)
        if cfg.altitude_m is not None:
            from dataclasses import replace

            self.params = replace(self.params, altitude_m=float(cfg.altitude_m))
        cfg.limits.validate()
        self.strategy = make_strategy(cfg.strategy)
        self.state = VehicleState()
        self.watchdog = LinkWatchdog(cfg.limits.link_timeout_s)
        self.result = MissionResult(strategy=cfg.strategy, wind=cfg.wind)
        self.upwind = UpwindFilter(self.params)
        self.estimator: WindEstimator | None = None
        self.adapter: MavlinkWindAdapter | None = None
        if cfg.wind == "estimated":
            from vehicle.params import load_vehicle

            self._vehicle_params = load_vehicle(cfg.vehicle)
            self.estimator = WindEstimator(self._vehicle_params)
            self.adapter = MavlinkWindAdapter(self.estimator)
        self._est_gate = GroundGate()
        self.est_watch = EstimatorWatch()
        self._unsubscribe: list[tuple[Any, Any]] = []
        self._imu_claimed = ""
        self._highres_t0 = math.nan
        self._tick_event: asyncio.Event | None = None  # set while searching
        self._next_tick = math.inf
        self._dt = 1.0 / self.params.rate_hz
        self._sysid = 0
        self._pending_vel: list[_Msg] = []
        self._outbox: list[tuple[str, str]] = []  # (message_name, fields_json) for mavlink_direct
        self._published_state = ""
        self._publish_failed = False
        self.direct: Any = None

    # ------------------------------------------------------------------ output
    def say(self, line: str) -> None:
        if line.startswith(("ABORT", "LINK", "SAFETY")):
            self.result.reasons.append(line)
        self.cfg.say(f"mission: {line}")

    def _wall(self, vehicle_s: float) -> float:
        """Wall seconds a vehicle-time duration takes at the speed hint (with slack)."""
        return 2.0 + vehicle_s / max(self.cfg.speed_hint, 1e-3)

    # ------------------------------------------------------------------ telemetry
    def _on_message(self, m: Any) -> None:
        self.watchdog.feed(time.monotonic())
        name = m.message_name
        try:
            f = json.loads(m.fields_json)
        except ValueError:
            return
        st = self.state
        if "time_usec" in f:
            t = f["time_usec"] * 1e-6
        elif "time_boot_ms" in f:
            t = f["time_boot_ms"] * 1e-3
        else:
            t = math.nan
        if name in ("HIL_SENSOR", "HIGHRES_IMU") and name != self._imu_claimed:
            # HIL_SENSOR carries every IMU sample (the project's SITL); HIGHRES_IMU (PX4) is the
            # fallback when no HIL_SENSOR has come within 1 s of it.
            if self._imu_claimed or not math.isfinite(t):
                return
            if name == "HIGHRES_IMU":
                self._highres_t0 = t if math.isnan(self._highres_t0) else self._highres_t0
                if t - self._highres_t0 < 1.0:
                    return
            self._imu_claimed = name
        if math.isfinite(t) and name != "WIND_COV" and not t < st.t:
            st.t = t
        if self.adapter is not None and name in ESTIMATOR_MESSAGES:
            self._feed_estimator(name, f, t)
        if name == "LOCAL_POSITION_NED":
            st.pos = np.array([f["x"], f["y"], f["z"]], dtype=float)
            st.vel = np.array([f["vx"], f["vy"], f["vz"]], dtype=float)
            st.new_position.set()
            if self._tick_event is not None and st.t + 1e-9 >= self._next_tick:
                self._next_tick = max(self._next_tick + self._dt, st.t - 0.5 * self._dt)
                self._tick()
        elif name == "ATTITUDE_QUATERNION":
            w, x, y, z = f["q1"], f["q2"], f["q3"], f["q4"]
            st.yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        elif name == "NAMED_VALUE_FLOAT":
            if str(f.get("name", "")).rstrip("\x00") == "CHEM":
                st.chem = float(f["value"])
                st.chem_seq += 1
        elif name == "HEARTBEAT":
            if int(f.get("autopilot", 8)) == 8:  # MAV_AUTOPILOT_INVALID: a ground station or companion
                return
            self._sysid = int(m.system_id)
            st.armed = bool(int(f["base_mode"]) & px4_modes.SAFETY_ARMED)
            mode = px4_modes.name(int(f["custom_mode"]))
            if mode != st.mode and st.mode:
                self.cfg.say(f"mission: autopilot mode {st.mode} -> {mode}")
            st.mode = mode
            st.heartbeats += 1
        elif name == "EXTENDED_SYS_STATE":
            st.landed = int(f["landed_state"])
        elif name == "STATUSTEXT":
            self.cfg.say(f"autopilot: {str(f.get('text', '')).rstrip(chr(0))}")
        elif name == "WIND_COV":
            var_h, var_v = float(f["var_horiz"]), float(f["var_vert"])
            w = np.array([f["wind_x"], f["wind_y"], f["wind_z"]], dtype=float)
            st.wind_cov = (st.t, w, np.diag([var_h / 2, var_h / 2, var_v]))

    def _feed_estimator(self, name: str, f: dict[str, Any], t: float) -> None:
        """Hand a message to the adapter, velocities only once the IMU has caught up with them.

        An autopilot sends its state messages (time of the newest state) ahead of the raw IMU
        samples of the same interval; fed at once, a velocity would move the filter past IMU
        samples still to come, and those would be rejected as older than the filter.
        """
        pend = self._pending_vel
        # Paused on the ground and while landing, cold-started at lift-off (estimator.ground_gate).
        action = self._est_gate.admit(withheld(self.state.landed))
        if action == "pause":
            pend.clear()
            return
        if action == "restart":
            self.estimator = WindEstimator(self._vehicle_params)
            self.adapter = MavlinkWindAdapter(self.estimator)
        if name == "LOCAL_POSITION_NED":
            pend.append(_Msg(name, f))
        else:
            self.adapter.handle(_Msg(name, f))
        est_t = self.estimator.t
        while pend and (est_t is None or pend[0].time_boot_ms * 1e-3 <= est_t + 1e-9
                        or len(pend) > 30):  # no IMU flowing (1 s at 30 Hz): do not hold velocities forever
            self.adapter.handle(pend.pop(0))

    async def _wait(self, pred: Callable[[], bool], vehicle_s: float, what: str, wall_s: float | None = None) -> bool:
        """Wait until ``pred()`` (checked at every position message) or ``vehicle_s`` of vehicle time
        (or ``wall_s``, or the link watchdog) runs out. Returns False on timeout; raises nothing."""
        st = self.state
        t0 = st.t
        wall_end = time.monotonic() + (self._wall(vehicle_s) if wall_s is None else wall_s)
        while not pred():
            st.new_position.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(st.new_position.wait(), 0.2)
            now = time.monotonic()
            if (math.isfinite(t0) and st.t - t0 > vehicle_s) or now > wall_end:
                return False
            if self.watchdog.check(now) is not None:
                return False
        return True

    # ------------------------------------------------------------------ mission
    async def run(self) -> MissionResult:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

        wall0 = time.monotonic()
        cfg = self.cfg
        try:
            async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
                await sdk.add_any_connection(cfg.connect)
                drone = await find_autopilot(sdk, self.cfg.connect_timeout_s)
                if drone is None:
                    raise MissionError(f"no autopilot heartbeat on {cfg.connect} within {cfg.connect_timeout_s:g} s")
                try:
                    await self._fly(drone)
                finally:
                    for plugin, handle in self._unsubscribe:
                        plugin.unsubscribe_message(handle)
                    await asyncio.sleep(0)  # let callbacks already queued run before the loop closes
        finally:
            self.result.wall_s = round(time.monotonic() - wall0, 2)
        return self.result

    async def _fly(self, drone: Any) -> None:
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        cfg, st, res = self.cfg, self.state, self.result
        tel, action, offb = TelemetryAsync(drone), ActionAsync(drone), OffboardAsync(drone)
        direct, param = MavlinkDirectAsync(drone), ParamAsync(drone)
        self.action, self.offb, self.direct = action, offb, direct
        names = DIRECT_MESSAGES + (("WIND_COV",) if cfg.wind == "mavlink" else ())
        # One callback for every subscription, run on the event loop in arrival order: the
        # estimator needs its inputs in time order across message types (an async generator per
        # message type would deliver them in per-type batches).
        loop = asyncio.get_running_loop()
        plugin = direct._plugin  # the synchronous plugin behind the asyncio wrapper

        def deliver(m: Any, _user: Any) -> None:
            loop.call_soon_threadsafe(self._on_message, m)

        self._unsubscribe = [(plugin, plugin.subscribe_message(n, deliver)) for n in names]
        if not await self._wait(lambda: st.heartbeats > 0, math.inf, "heartbeat", cfg.connect_timeout_s):
            raise MissionError("no HEARTBEAT through mavlink_direct")
        self.say(f"connected to system {self._sysid} on {cfg.connect}")

        async def healthy() -> None:
            async for ok in tel.subscribe_health_all_ok():
                if ok:
                    return

        try:
            await asyncio.wait_for(healthy(), cfg.health_timeout_s)
        except TimeoutError:
            raise MissionError(f"autopilot not healthy within {cfg.health_timeout_s:g} s") from None
        if not await self._wait(lambda: st.pos is not None, math.inf, "position", cfg.connect_timeout_s):
            raise MissionError("no LOCAL_POSITION_NED / HEARTBEAT over mavlink_direct")
        if st.armed or st.landed == LANDED_IN_AIR:
            raise MissionError("the vehicle is already armed or flying: start the mission on the ground, disarmed")
        await self._ensure_datalink_failsafe(param)

        home = st.pos.copy()
        res.home_ned = [round(float(v), 3) for v in home]
        sup = Supervisor(cfg.limits, home)
        self.sup = sup
        alt = sup.altitude_target(self.params.altitude_m)
        if alt != self.params.altitude_m:
            self.say(f"SAFETY: search altitude {self.params.altitude_m:g} m clamped to {alt:g} m by the limits")
        self.strategy.reset(home, self.params, seed=cfg.seed)

        # ---- arm and take off
        await action.set_takeoff_altitude(alt)
        await action.arm()
        t_arm = st.t
        self.t_arm = t_arm
        self.say(f"armed at t = {t_arm:.2f} s; taking off to {alt:g} m")
        await action.takeoff()
        ok = await self._wait(lambda: st.mode == "AUTO.LOITER" and st.landed == LANDED_IN_AIR
                              and abs(-(st.pos[2] - home[2]) - alt) < 0.5, cfg.takeoff_timeout_s, "take-off")
        if not ok:
            await self._abort(Abort("takeoff-failed", f"take-off to {alt:g} m did not finish within "
                                    f"{cfg.takeoff_timeout_s:g} s (mode {st.mode})"))  # fmt: skip
            return
        self.say(f"take-off complete at t = {st.t:.2f} s")

        # ---- search
        abort = await self._search(offb, home, t_arm)
        self._tick_event = None  # no more strategy ticks
        if abort is not None:
            await self._abort(abort)
            return
        await self._land_at_declared()

    async def _ensure_datalink_failsafe(self, param: Any) -> None:
        """Make sure the autopilot lands on a data-link loss (PX4 NAV_DLL_ACT = 3) before take-off."""
        value = None
        for getter in (param.get_param_int, param.get_param_float):
            try:
                value = await asyncio.wait_for(getter("NAV_DLL_ACT"), 5.0)
                break
            except Exception:  # noqa: BLE001 - wrong type or unknown parameter: try the other, then give up
                continue
        if value is None:
            self.say("SAFETY: the autopilot has no NAV_DLL_ACT parameter: a link loss is left to its own failsafe")
            return
        if int(value) == 0:
            for setter in (param.set_param_int, param.set_param_float):
                try:
                    await asyncio.wait_for(setter("NAV_DLL_ACT", 3 if setter is param.set_param_int else 3.0), 5.0)
                    self.say("SAFETY: NAV_DLL_ACT was 0 (disabled): set to 3 (land on data-link loss)")
                    return
                except Exception:  # noqa: BLE001
                    continue
            self.say("SAFETY: could not enable NAV_DLL_ACT: a link loss is left to the autopilot's defaults")

    def _wind_info(self) -> WindInfo | None:
        mode = self.cfg.wind
        if mode == "none":
            return None
        if mode == "estimated":
            est = self.estimator
            if est.t is None:
                return self.upwind.make(np.zeros(3), np.eye(3) * 100.0)
            return self.upwind.make(est.wind_ned, est.wind_cov)
        wc = self.state.wind_cov
        if wc is None or self.state.t - wc[0] > 5.0:
            return self.upwind.make(np.zeros(3), np.eye(3) * 100.0)
        return self.upwind.make(wc[1], wc[2])

    def _estimator_fault(self, t: float) -> Abort | None:
        if self.cfg.wind == "estimated":
            est = self.estimator
            return self.est_watch.check(t, est.wind_ned, est.wind_cov, dict(est.rejected), est.accepted["imu"])
        if self.cfg.wind == "mavlink":
            wc = self.state.wind_cov
            if wc is not None and t - wc[0] > 5.0:
                return Abort("estimator-fault", f"WIND_COV stopped {t - wc[0]:.1f} s ago")
        return None

    def _tick(self) -> None:
        """One strategy tick at vehicle time ``state.t`` (called from the LOCAL_POSITION_NED handler,
        so ticks follow the vehicle's clock even when the loop works through a backlog). Leaves the
        setpoint, or the reason to stop, for :meth:`_search` to act on."""
        st, res, sup, p, k = self.state, self.result, self.sup, self.params, self._k
        t = st.t
        wind = self._wind_info()
        abort = (sup.check_time(t - k["t_arm"]) or sup.check_vehicle(st.pos) or self._estimator_fault(t))
        if abort is None and not st.armed:
            abort = Abort("landed", f"the vehicle disarmed during the search (mode {st.mode})")
        if abort is not None:
            k["abort"] = abort
            self._tick_event.set()
            return
        if not k["searching"]:
            waiting = wind is not None and not math.isfinite(wind.upwind_rad)
            if waiting and t - k["t_air"] < p.wind_wait_s:
                return
            k["searching"] = True
            self.say(f"no usable wind direction after {p.wind_wait_s:g} s: searching without it" if waiting
                     else f"wind direction usable at t = {t:.2f} s: starting the search")  # fmt: skip
        pos = st.pos.copy()
        if k["prev"] is not None:
            k["path"] += float(np.hypot(*(pos[0:2] - k["prev"][0:2])))
        k["prev"] = pos
        obs = Observation(t=t, position_ned=pos, velocity_ned=st.vel.copy(), chem_mg_m3=st.chem,
                          detected=st.chem > 0.0, chem_new=st.chem_seq != k["chem_seen"], wind=wind)  # fmt: skip
        k["chem_seen"] = st.chem_seq
        sp = self.strategy.update(obs)
        res.ticks += 1
        if sp.declared_source_ned is not None and res.declared_ned is None:
            res.declared_ned = [round(float(v), 3) for v in sp.declared_source_ned]
            res.confidence = round(float(sp.confidence), 3)
            res.time_s = round(float(sp.info.get("t_declared", t)) - k["t_arm"], 2)
            res.path_m = round(k["path"], 2)
            self.say(f"source declared at N {res.declared_ned[0]:.1f} E {res.declared_ned[1]:.1f} m "
                     f"(confidence {res.confidence:.2f}) at t = {res.time_s:.1f} s")  # fmt: skip
        if res.declared_ned is None:
            res.path_m = round(k["path"], 2)
        res.state = sp.state
        if sp.state and sp.state != self._published_state:  # published by _search, in this order
            self._published_state = sp.state
            self._outbox.append(state_fields(sp.state))
        if res.declared_ned is not None and not k["declaration_queued"]:
            k["declaration_queued"] = True
            self._outbox += declaration_fields(t, res.declared_ned, res.confidence)
        k["sp"] = sp
        try:  # sent at once, from the tick: the synchronous MAVSDK call only queues the message
            self._send_sync(sp.position_ned, sp.velocity_ned, sp.yaw_rad)
            res.setpoints += 1
        except Exception as e:  # noqa: BLE001 - OffboardError (or a closed link): stop the search
            k["abort"] = Abort("offboard-rejected", f"the autopilot rejected the offboard setpoint: {e}")
        self._tick_event.set()

    async def _search(self, offb: Any, home: np.ndarray, t_arm: float) -> Abort | None:
        """Run the strategy (ticks: :meth:`_tick`) and send its setpoints until it is done or a
        safety rule stops it."""
        from mavsdk.asyncio.plugins.offboard import OffboardError

        cfg, st, res = self.cfg, self.state, self.result
        self._k = {"t_arm": t_arm, "t_air": st.t, "searching": False, "path": 0.0, "prev": None,
                   "chem_seen": st.chem_seq, "sp": None, "abort": None, "declaration_queued": False}  # fmt: skip
        self._tick_event = asyncio.Event()
        self._next_tick = st.t
        offboard = False
        t_off0 = math.nan
        n0 = 0
        while True:
            self._tick_event.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._tick_event.wait(), min(0.5, cfg.limits.link_timeout_s))
            await self._publish()
            if (a := self.watchdog.check(time.monotonic())) is not None:
                return a
            if self._k["abort"] is not None:
                return self._k["abort"]
            sp = self._k["sp"]
            if sp is None:
                continue
            if not offboard:
                try:  # PX4 wants the setpoint stream before the mode switch: the tick sent one
                    await offb.start()
                except OffboardError as e:
                    return Abort("offboard-rejected", f"the autopilot rejected offboard control: {e}")
                offboard, t_off0, n0 = True, st.t, res.setpoints
            if st.t > t_off0:
                res.setpoint_rate_hz = round((res.setpoints - n0) / (st.t - t_off0), 2)
                res.tick_rate_hz = round(res.ticks / (st.t - t_off0), 2)
            if st.mode and st.mode != "OFFBOARD" and st.t - t_off0 > 1.5:
                return Abort("offboard-lost", f"the vehicle left offboard on its own (mode {st.mode})")
            if sp.done:
                if res.declared_ned is None:
                    return Abort("search-ended", f"the strategy ended without a declaration (state {sp.state})")
                return None

    async def _publish(self) -> None:
        """Send what the ticks queued (strategy state changes, the declaration) over MAVLink:
        STATUSTEXT ``state: NAME`` and NAMED_VALUE_FLOAT SRC_N/E/D/CONF (:mod:`wire.names`),
        so a ground station, a tlog and ``windseek sitl --rrd`` see them. A failed send is said once
        and never stops the mission."""
        if not self._outbox or self.direct is None:
            return
        pairs, self._outbox = self._outbox, []
        try:
            await publish(self.direct, pairs)
        except Exception as e:  # noqa: BLE001 - MavlinkDirectError, a closed link
            if not self._publish_failed:
                self._publish_failed = True
                self.say(f"could not publish {pairs[0][0]} over MAVLink ({e}); the mission goes on")

    def _send_sync(self, pos: np.ndarray | None, vel: np.ndarray | None, yaw: float | None) -> None:
        """Clamp and send one offboard setpoint through the synchronous plugin (m, m/s, rad, NED)."""
        from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw

        st, plugin = self.state, self.offb._plugin
        if pos is None and vel is None:
            pos = st.pos.copy()
        pos, vel = self.sup.clamp(pos, vel, st.pos)
        yaw_deg = math.degrees(st.yaw if yaw is None else yaw)
        self.result.clamped_setpoints = self.sup.clamped
        if pos is not None and vel is not None:
            plugin.set_position_velocity_ned(PositionNedYaw(*map(float, pos), yaw_deg),
                                             VelocityNedYaw(*map(float, vel), yaw_deg))  # fmt: skip
        elif pos is not None:
            plugin.set_position_ned(PositionNedYaw(*map(float, pos), yaw_deg))
        else:
            plugin.set_velocity_ned(VelocityNedYaw(*map(float, vel), yaw_deg))

    async def _send(self, offb: Any, pos: np.ndarray | None, vel: np.ndarray | None, yaw: float | None) -> None:
        from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw

        st = self.state
        if pos is None and vel is None:
            pos = st.pos.copy()
        pos, vel = self.sup.clamp(pos, vel, st.pos)
        yaw_deg = math.degrees(st.yaw if yaw is None else yaw)
        self.result.clamped_setpoints = self.sup.clamped
        if pos is not None and vel is not None:
            await offb.set_position_velocity_ned(PositionNedYaw(*map(float, pos), yaw_deg),
                                                 VelocityNedYaw(*map(float, vel), yaw_deg))  # fmt: skip
        elif pos is not None:
            await offb.set_position_ned(PositionNedYaw(*map(float, pos), yaw_deg))
        else:
            await offb.set_velocity_ned(VelocityNedYaw(*map(float, vel), yaw_deg))

    # ------------------------------------------------------------------ endings
    async def _land_at_declared(self) -> None:
        """Fly over the declared source (offboard, at the current height), land there, wait for the disarm."""
        st, res = self.state, self.result
        target = np.array(res.declared_ned, dtype=float)
        target[2] = st.pos[2]

        def over() -> bool:
            return float(np.hypot(*(st.pos[0:2] - target[0:2]))) < 0.5 and float(np.linalg.norm(st.vel)) < 0.5

        t_end = st.t + 20.0
        while not over() and st.t < t_end and self.watchdog.check(time.monotonic()) is None:
            await self._send(self.offb, target, None, None)
            await self._wait(lambda: False, 0.1, "tick")
        res.cause = "declared"
        self.say("over the declared source: landing")
        await self._land(hold_first=False)

    async def _abort(self, abort: Abort) -> None:
        """Say why, then hold and land (or, on a link loss, wait for the link and do it then)."""
        res = self.result
        res.cause = abort.cause
        self.say(abort.line())
        if abort.cause == "link-lost":
            await self._after_link_loss()
            return
        await self._land(hold_first=True)

    async def _after_link_loss(self) -> None:
        st, cfg = self.state, self.cfg
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self.offb.stop(), 1.0)  # stop MAVSDK repeating the last setpoint
        end = time.monotonic() + cfg.link_grace_s
        while time.monotonic() < end:
            if self.watchdog.silent_s(time.monotonic()) < 0.5:
                break
            await asyncio.sleep(0.1)
        else:
            self.say(f"LINK: still down after {cfg.link_grace_s:g} s: the autopilot's failsafe is in charge")
            self._final()
            return
        self.say("LINK: telemetry is back")
        if not st.armed:
            self.say("LINK: the vehicle already landed and disarmed (autopilot failsafe)")
            self._final()
            return
        await self._land(hold_first=True)

    async def _land(self, hold_first: bool) -> None:
        st, cfg = self.state, self.cfg
        try:
            if hold_first:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(self.offb.stop(), 3.0)
                if st.mode not in ("AUTO.LOITER", "AUTO.LAND"):
                    await asyncio.wait_for(self.action.hold(), 3.0)
                self.say(f"holding for {cfg.hold_s:g} s, then landing")
                await self._wait(lambda: False, cfg.hold_s, "hold")
            if st.armed and st.mode != "AUTO.LAND":
                await asyncio.wait_for(self.action.land(), 3.0)
        except Exception as e:  # noqa: BLE001 - report and keep watching: the autopilot may still land
            self.say(f"SAFETY: land command failed ({e}); waiting for the autopilot")
        ok = await self._wait(lambda: not st.armed, cfg.land_timeout_s, "disarm")
        self.say("landed and disarmed" if ok else f"not disarmed within {cfg.land_timeout_s:g} s (mode {st.mode})")
        self._final()

    def _final(self) -> None:
        st, res = self.state, self.result
        res.disarmed = not st.armed
        res.landed = st.landed == LANDED_ON_GROUND or not st.armed
        res.final_ned = None if st.pos is None else [round(float(v), 3) for v in st.pos]
        if math.isfinite(st.t) and hasattr(self, "t_arm"):
            res.mission_time_s = round(st.t - self.t_arm, 2)
        t_arm = getattr(self, "t_arm", 0.0)
        res.verifications = [
            {"t_start_s": round(v.t_start - t_arm, 2),
             "duration_s": round(v.end(st.t) - v.t_start, 2), "outcome": v.outcome,
             "candidate_ne": [round(c, 3) for c in v.candidate_ne]}
            for v in getattr(self.strategy, "verifications", [])]  # fmt: skip
        if self.estimator is not None:
            est = self.estimator
            res.wind_ned = [round(float(v), 3) for v in est.wind_ned]
            res.estimator = {"accepted": dict(est.accepted), "rejected": dict(est.rejected),
                             "imu_message": self._imu_claimed,
                             "span_s": est.span_s}  # fmt: skip
        elif self.state.wind_cov is not None:
            res.wind_ned = [round(float(v), 3) for v in self.state.wind_cov[1]]


async def run_mission(cfg: MissionConfig) -> MissionResult:
    """Fly one search mission through MAVSDK; see the module docstring. Raises :class:`MissionError`
    when it cannot start; safety stops are not errors (``result.cause`` says why)."""
    return await MavsdkMission(cfg).run()
