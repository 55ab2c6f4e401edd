"""MAVSDK runner: the same strategy objects and the same mission loop as the in-process runner,
flown through an autopilot in real time.

``await run_mission(MissionConfig(...))`` (or ``windseek mission --connect URL --strategy NAME``)
connects with MAVSDK (``mavsdk.asyncio``, 4.x) over UDP, TCP or serial
(:class:`~mission.runners.mavsdk_vehicle.MavsdkVehicle`), makes sure the autopilot lands on a
data-link loss (``NAV_DLL_ACT``, set with its real parameter type and read back), and flies the
one mission loop (:mod:`mission.loop`): take-off, wind wait, strategy ticks at ``rate_hz`` of
*vehicle* time, declaration, landing over the declared source.

Wind modes: ``estimated`` (the UKF run live on the telemetry in a worker thread; paused on the
ground; default), ``mavlink`` (WIND_COV from the autopilot or a relayed ``windseek estimator``),
``none`` (pure chemotaxis); see :mod:`mission.runners.live_wind`. There is no oracle over MAVLink.

What the runner publishes (:mod:`wire.names`, through ``mavlink_direct``, from the MAVSDK
ground-station identity): the strategy state on every change as STATUSTEXT ``state: NAME``, and the
declaration once as NAMED_VALUE_FLOAT ``SRC_N``, ``SRC_E``, ``SRC_D`` (m, NED), then ``SRC_CONF``.

Safety (:mod:`mission.safety`): setpoints clamped into the geofence box and altitude band; the
vehicle outside the box, the time limit, an estimator fault or an offboard rejection stop the
search with one ``ABORT (cause): why`` line, and the vehicle holds, then lands where it is. A link
loss leaves the vehicle to the autopilot's failsafes; if the link comes back, the runner looks at
the vehicle again (a fresh HEARTBEAT) before it does anything, and reports what it saw.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from mission.loop import LoopConfig, MissionLoop, MissionWind
from mission.result import MissionError, MissionResult
from mission.runners import ardupilot
from mission.runners.fence import SiteBuildings, place_buildings
from mission.runners.field_solver import field_solver_for, warmed
from mission.runners.live_wind import ESTIMATOR_MESSAGES, EstimatedLiveWind, NoLiveWind, WindCovWind
from mission.runners.mavsdk_vehicle import LinkConfig, MavsdkVehicle
from mission.safety import SafetyLimits
from mission.strategies import make_strategy
from mission.strategies.params import CommonParams, load_params
from mission.vehicle import CommandError
from mission.wind_modes import LIVE_WIND_MODES
from mission.wind_source import UpwindFilter
from vehicle.vehicle_file import load_vehicle

#: PX4's data-link-loss action parameter (INT32 on PX4) and the value the runner needs: land.
DLL_PARAM, DLL_LAND = "NAV_DLL_ACT", 3
#: The system id MAVSDK takes as a ground station (``ComponentType.GROUND_STATION``: 245, component 190).
MAVSDK_GCS_SYSID = 245
#: Wall seconds the runner waits, before take-off, for the urban field's worker to warm up (a spawned process:
#: imports and numba kernels, 2-10 s on a loaded machine; mission.runners.field_solver.warmed).
WARM_LIMIT_S = 60.0

__all__ = ["MissionConfig", "MissionError", "MissionResult", "run_mission"]


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
    esc_component: the estimator's rotor telemetry from this component (158 with ``windseek sitl --px4``);
        None: the autopilot's own.
    buildings: a scenario's buildings (:class:`mission.runners.fence.SiteBuildings`): placed in the
        autopilot's local frame from its HOME_POSITION, uploaded as geofence exclusion zones and
        kept clear by the safety supervisor; None: open field.
    say: where the runner's lines go (default print).
    observe: called with the mission loop once it exists, before it flies: a listener (e.g.
        :class:`recording.mission_rrd.MissionRecorder`, ``windseek mission --rrd``) hooks itself onto
        the loop's ``on_tick`` and its vehicle; None: nobody listens.
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
    esc_component: int | None = None
    say: Callable[[str], None] = print
    signing_key: Any = None  # wire.signing.SigningKey: MAVLink 2 signing on the link (None: off)
    buildings: SiteBuildings | None = None
    observe: Callable[[MissionLoop], None] | None = None


async def run_mission(cfg: MissionConfig) -> MissionResult:
    """Fly one search mission through MAVSDK; see the module docstring. Raises :class:`MissionError`
    when it cannot start; safety stops are not errors (``result.cause`` says why)."""
    if cfg.wind not in LIVE_WIND_MODES:
        raise ValueError(f"wind mode {cfg.wind!r}: choose one of {', '.join(LIVE_WIND_MODES)}")
    cfg.limits.validate()
    params = cfg.params if cfg.params is not None else load_params(cfg.strategy)
    if cfg.altitude_m is not None:
        params = replace(params, altitude_m=float(cfg.altitude_m))
    wall0 = time.monotonic()
    link = LinkConfig(cfg.connect, cfg.connect_timeout_s, cfg.health_timeout_s, cfg.limits.link_timeout_s,
                      cfg.speed_hint, signing_key=cfg.signing_key)  # fmt: skip
    estimated: EstimatedLiveWind | None = None
    solver: ProcessPoolExecutor | None = None
    extra: tuple[str, ...] = ()
    sink = None
    upwind = UpwindFilter(params)
    if cfg.wind == "estimated":
        extra = ESTIMATOR_MESSAGES
        estimated = EstimatedLiveWind(load_vehicle(cfg.vehicle), upwind,  # before any telemetry arrives
                                      esc_component=cfg.esc_component)  # fmt: skip
        sink = estimated.sink
    elif cfg.wind == "mavlink":
        extra = ("WIND_COV",)
    try:
        async with MavsdkVehicle(link, cfg.say, sink, extra) as v:
            wind: MissionWind = estimated or (WindCovWind(v, upwind) if cfg.wind == "mavlink" else NoLiveWind())
            obstacles = None
            if cfg.buildings is not None:
                try:
                    obstacles = await place_buildings(cfg.buildings, lambda: v.home, v.drone, cfg.say,
                                                      max(10.0, 5.0 / cfg.speed_hint))  # fmt: skip
                except CommandError as e:
                    raise MissionError(f"buildings: {e}") from None
            strategy = make_strategy(cfg.strategy)
            solver = field_solver_for(strategy, params, obstacles)  # the urban field off the event loop
            if solver is not None:
                await warmed(solver, WARM_LIMIT_S, cfg.say)
            loop = MissionLoop(v, strategy, params, wind, cfg.limits,
                               LoopConfig(cfg.takeoff_timeout_s, cfg.land_timeout_s, cfg.hold_s, cfg.link_grace_s),
                               seed=cfg.seed, obstacles=obstacles)  # fmt: skip
            loop.result.strategy = cfg.strategy
            if cfg.observe is not None:
                cfg.observe(loop)
            if v.ardupilot:
                await ardupilot.ensure_gcs_failsafe(v, loop.say, MAVSDK_GCS_SYSID)
            else:
                await _ensure_datalink_failsafe(v, loop.say)
            lags: list[float] = []
            probe = asyncio.create_task(_loop_lag(lags))
            try:
                res = await loop.run()
            finally:
                probe.cancel()
            if lags:
                res.loop_lag_max_ms = round(max(lags), 1)
                res.loop_lag_p99_ms = round(float(np.percentile(lags, 99)), 1)
            res.estimator.update({f"link_{k}": n for k, n in v.counters.items()})
    finally:
        if estimated is not None:
            estimated.stop()
        if solver is not None:
            solver.shutdown(wait=False, cancel_futures=True)
    res.wall_s = round(time.monotonic() - wall0, 2)
    return res


async def _loop_lag(lags: list[float], period_s: float = 0.02) -> None:
    """How late the event loop wakes from ``period_s`` sleeps (ms), appended to ``lags`` (bounded)."""
    while True:
        t0 = time.monotonic()
        await asyncio.sleep(period_s)
        if len(lags) < 200_000:
            lags.append(max(0.0, (time.monotonic() - t0 - period_s) * 1e3))


async def _ensure_datalink_failsafe(v: MavsdkVehicle, say: Callable[[str], None]) -> None:
    """Make sure the autopilot lands on a data-link loss (PX4 ``NAV_DLL_ACT`` = 3) before take-off.

    PX4 has INT32 and REAL32 parameters and refuses a set of the wrong type, so the type is learned
    by reading (MAVSDK's typed getters fail on the other type), the value set with the matching
    setter, and read back to verify."""
    param, timeout = v.param, v.cfg.command_timeout_s
    kind, value = "", math.nan
    for k, getter in (("int", param.get_param_int), ("float", param.get_param_float)):
        try:
            value = float(await asyncio.wait_for(getter(DLL_PARAM), timeout))
            kind = k
            break
        except Exception:  # noqa: BLE001 - wrong type or unknown: try the other, then give up
            continue
    if not kind:
        say(f"SAFETY: the autopilot has no {DLL_PARAM} parameter: a link loss is left to its own failsafe")
        return
    if int(value) != 0:
        say(f"{DLL_PARAM} = {int(value)} ({kind}): the autopilot's data-link-loss failsafe is on")
        return
    try:
        if kind == "int":
            await asyncio.wait_for(param.set_param_int(DLL_PARAM, DLL_LAND), timeout)
            back = float(await asyncio.wait_for(param.get_param_int(DLL_PARAM), timeout))
        else:
            await asyncio.wait_for(param.set_param_float(DLL_PARAM, float(DLL_LAND)), timeout)
            back = float(await asyncio.wait_for(param.get_param_float(DLL_PARAM), timeout))
    except Exception as e:  # noqa: BLE001 - ParamError, a timeout
        say(f"SAFETY: could not enable {DLL_PARAM} ({e}): a link loss is left to the autopilot's defaults")
        return
    if int(back) != DLL_LAND:
        say(f"SAFETY: {DLL_PARAM} read back as {back:g} after setting {DLL_LAND}: a link loss is left to "
            "the autopilot's defaults")  # fmt: skip
        return
    say(f"{DLL_PARAM} was 0 (disabled): set to {DLL_LAND} (land on data-link loss), read back")
