"""In-process runner: simulator + (estimator) + strategy in lockstep, no I/O, for batch evaluation.

One trial is the one mission loop (:mod:`mission.loop`) flying the simulation through the
lockstep adapter (:class:`~mission.runners.lockstep.LockstepVehicle`): arm, take off to the
strategy's search altitude, hover until the wind source gives a direction, then every strategy
tick (``rate_hz``, 10 Hz by default) the strategy on the latest GNSS fix and chemical reading,
its setpoint clamped into the limits and sent to the built-in autopilot. Stops on completion
(declared + descended), the time limit (the scenario's duration), a geofence exit (a box of
``geofence_m`` around home) or a crash; the trial is then scored against the truth.

Observation inputs are only what a real vehicle has: the latest GNSS fix (position and
velocity, with the receiver's noise and 0.1 s latency), the chemical reading, and the wind
source (the simulator's truth only in the explicit ``oracle`` mode). The true source position
is read only to score the result.

Units SI, frames NED; times are simulation seconds from t = 0 (on the ground, before take-off).
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from mission.loop import LoopConfig, MissionLoop
from mission.obstacles import Obstacles
from mission.runners.lockstep import InProcessWind, LockstepVehicle
from mission.safety import SafetyLimits
from mission.strategies import make_strategy
from mission.strategies.params import CommonParams, load_params
from mission.wind_source import make_wind_source
from sitl.scenario import Scenario, load_scenario
from sitl.simulation import Simulation
from vehicle.vehicle_file import load_vehicle

#: A declaration within this horizontal distance of the true source is a success [m] (the
#: bio-inspired strategies' tables; ``SUCCESS_RADIUS_BY_STRATEGY`` overrides it per strategy).
SUCCESS_RADIUS_M = 5.0
#: Success radius of the strategies that claim a tighter localization (issue 19: infotaxis) [m].
SUCCESS_RADIUS_BY_STRATEGY = {"infotaxis": 3.0}
#: The vehicle has *reached* the source once it comes within this horizontal distance [m]
#: (``reach_path_m``; issue 19's path measure, separate from the success radius).
REACH_RADIUS_M = 2.0
#: The take-off must end within this many simulated seconds.
TAKEOFF_TIMEOUT_S = 30.0
#: Loop abort causes and the trial failure cause each one scores as.
_CAUSE = {"time-limit": "timeout", "takeoff-failed": "takeoff", "geofence": "geofence", "crash": "crash",
          "search-ended": "timeout", "landed": "crash"}  # fmt: skip

#: The estimator is fed the mean of this many consecutive 250 Hz IMU samples (125 Hz): half
#: the UKF cost with the same direction accuracy (filtered upwind direction error rms 6.6 deg
#: at 250 Hz, 6.4 deg at 125 Hz, open-field seeds 100-101, surge-cast flights).
IMU_DECIMATION = 2

FAILURE_CAUSES = ("declared-far", "timeout", "geofence", "crash", "takeoff", "gave-up")


@dataclass
class TrialResult:
    """Outcome of one trial (SI units, NED, times from t = 0 on the ground).

    success: declared within ``success_radius_m`` of the true source, horizontally.
    declared_ned: the declared source position, or None.
    error_m: horizontal distance declared - true source (nan without a declaration).
    time_s: simulation time of the declaration (nan without one).
    path_m: horizontal path flown from the end of the take-off to the declaration (or the end).
    reach_path_m: horizontal path flown until the vehicle first came within ``REACH_RADIUS_M``
        of the source, horizontally (nan if it never did; counted on after a declaration, e.g.
        over the descent): the part of the path spent finding the source.
    success_radius_m: the success radius of this strategy (``SUCCESS_RADIUS_BY_STRATEGY``).
    credible_radius_m: radius of the declared credible region (the strategy's, e.g. 90 %), nan
        when the strategy states none; credible_contains: the true source lies inside it
        (scoring only; None without a region).
    wind_rmse_ned: RMSE [m/s] of the wind the strategy was given (N, E, D) against the true wind at
        the vehicle (turbulence included), over the search ticks; nan without wind information.
    start_distance_m: horizontal distance from the start to the true source.
    cause: "" on success, else one of FAILURE_CAUSES.
    verifications: the strategy's verification sweeps, in order, each a dict: ``t_start_s``,
        ``duration_s``, ``path_m`` (horizontal path flown during it), ``outcome``
        (``verified`` / ``interrupted``, ``""`` if the trial ended first) and
        ``candidate_error_m`` (horizontal distance of the candidate it tested from the true
        source; scoring only, the strategy never sees it).
    """

    scenario: str
    strategy: str
    wind: str
    seed: int
    success: bool
    declared_ned: list[float] | None
    confidence: float
    error_m: float
    time_s: float
    path_m: float
    start_distance_m: float
    cause: str
    end_state: str = ""
    n_detections: int = 0
    hit_rate_at_last: float = math.nan
    diag: dict = field(default_factory=dict)
    wall_s: float = 0.0
    track: list[list[float]] = field(default_factory=list)  # [t, n, e, d] per second when asked
    reach_path_m: float = math.nan
    verifications: list[dict] = field(default_factory=list)
    wind_rmse_ned: list[float] = field(default_factory=lambda: [math.nan] * 3)
    success_radius_m: float = SUCCESS_RADIUS_M
    credible_radius_m: float = math.nan
    credible_contains: bool | None = None
    #: The world's vehicle and force model ("nasa-quad: bet"), and the estimator's model (its vehicle file's
    #: name and where the model came from); empty when no estimator ran.
    world_truth: str = ""
    estimator_model: str = ""

    @property
    def path_ratio(self) -> float:
        return self.path_m / self.start_distance_m if self.start_distance_m > 0 else math.nan

    @property
    def reach_ratio(self) -> float:
        """``reach_path_m`` over the start distance."""
        return self.reach_path_m / self.start_distance_m if self.start_distance_m > 0 else math.nan

    def to_dict(self) -> dict:
        d = asdict(self)
        d["path_ratio"] = self.path_ratio
        d["reach_ratio"] = self.reach_ratio
        return d


def describe_model(source: object) -> str:
    """The estimator's force model of a wind source, in one line ('' when it runs no estimator)."""
    model = getattr(source, "_model", None)
    if model is None:
        return ""
    return f"{model.model_name}: {model.model_info.get('source', 'its vehicle file')}"


def run_trial(
    scenario: str | Scenario,
    strategy: str,
    wind: str = "estimated",
    seed: int | None = None,
    params: CommonParams | None = None,
    params_path: str | None = None,
    time_limit_s: float | None = None,
    geofence_m: float = 250.0,
    keep_track: bool = False,
    imu_decimation: int = IMU_DECIMATION,
    recorder: Any = None,
    model: str | None = None,
) -> TrialResult:
    """Fly one seeded search trial in lockstep and score it.

    Args:
        scenario: built-in scenario name, .toml path or Scenario (must have a ``[plume]``).
        strategy: a name of :data:`mission.strategies.STRATEGIES`.
        wind: ``estimated``, ``oracle`` or ``none``.
        seed: simulation seed (default: the scenario's); the strategy's seeded choices use it too.
        params / params_path: strategy parameters (default: the strategy's defaults).
        time_limit_s: simulated time limit (default: the scenario's duration).
        geofence_m: half-width of the horizontal box around home the trial must stay in [m].
        keep_track: record the position once per second in ``TrialResult.track``.
        imu_decimation: ``estimated`` mode: IMU samples averaged per estimator step (see
            ``IMU_DECIMATION``).
        recorder: a :class:`recording.trial.TrialRecorder` (or anything with ``attach(sim, vehicle,
            strategy, params)`` and ``finish(result)``): records the trial to a ``.rrd``.
        model: vehicle file (name or path) of the estimator's force model; default the world vehicle's own.
    """
    wall0 = time.perf_counter()
    sc = load_scenario(scenario) if isinstance(scenario, str) else scenario
    if sc.plume is None:
        raise ValueError(f"scenario {sc.name!r} has no [plume] table: nothing to search for")
    p = params if params is not None else load_params(strategy, params_path)
    sim = Simulation(sc, seed=seed, autostart_route=False, record_truth=(wind == "estimated"))
    seed = sim.seed
    strat = make_strategy(strategy)
    model_v = load_vehicle(model) if model else None
    source = make_wind_source(wind, sim, p, imu_decimation=imu_decimation, model=model_v)
    vehicle = LockstepVehicle(sim, source, p.rate_hz)
    limit = sc.duration_s if time_limit_s is None else float(time_limit_s)
    limits = SafetyLimits(box_min_ned=(-geofence_m, -geofence_m, -500.0), box_max_ned=(geofence_m, geofence_m, 0.0),
                          min_altitude_m=0.5, max_altitude_m=500.0, time_limit_s=limit)  # fmt: skip
    if recorder is not None:
        recorder.attach(sim, vehicle, strat, p)
    src = np.asarray(sim.chem.sources_ned[0] if sim.chem is not None else np.zeros(3), dtype=float)
    score = _Scorer(sim, src, p.rate_hz, keep_track, vehicle)
    vehicle.tick_hooks.append(score.every_tick)
    obstacles = Obstacles.from_buildings(sc.urban.buildings) if sc.urban is not None and sc.urban.buildings else None
    loop = MissionLoop(vehicle, strat, p, InProcessWind(vehicle), limits,
                       LoopConfig(takeoff_timeout_s=TAKEOFF_TIMEOUT_S, land_at_end=False), seed=seed,
                       on_tick=score.tick, obstacles=obstacles)  # fmt: skip
    res = asyncio.run(loop.run())
    home = np.array(res.home_ned if res.home_ned is not None else np.zeros(3), dtype=float)
    start_dist = float(np.hypot(*(src[0:2] - home[0:2])))
    declared = None if res.declared_ned is None else np.asarray(res.declared_ned, dtype=float)
    cause = "" if res.cause == "declared" else _CAUSE.get(res.cause, "timeout")
    radius = SUCCESS_RADIUS_BY_STRATEGY.get(strategy, SUCCESS_RADIUS_M)
    cred = float(res.credible_radius_m)
    if declared is not None:
        err = float(np.hypot(*(declared[0:2] - src[0:2])))
        success = err <= radius and cause != "crash"
        cause = "declared-far" if not success and not cause else ("" if success else cause)
        path = res.path_m
    else:
        err, success, path = math.nan, False, score.path
        cause = "gave-up" if res.state == "give-up" and cause in ("", "timeout") else (cause or "timeout")
    t_declared = loop.t_declared
    result = TrialResult(
        scenario=sc.name, strategy=strategy, wind=wind, seed=seed, success=success,
        declared_ned=res.declared_ned, confidence=res.confidence, error_m=err, time_s=t_declared, path_m=path,
        start_distance_m=start_dist, cause=cause, end_state=res.state,
        n_detections=_memory(strat)[0], hit_rate_at_last=round(_memory(strat)[1], 3),
        diag=getattr(strat, "diag", {}), wall_s=time.perf_counter() - wall0, track=score.track,
        world_truth=f"{sim.vehicle.name}: {sim.vehicle.truth}", estimator_model=describe_model(source),
        reach_path_m=score.reach_path,
        verifications=_verification_records(strat, src, sim.t, score.path_t, score.path_m),
        wind_rmse_ned=score.wind_rmse(),
        success_radius_m=radius, credible_radius_m=cred,
        credible_contains=None if declared is None or math.isnan(cred) else bool(err <= cred),
    )
    if recorder is not None:
        recorder.finish(result)
    return result


class _Scorer:
    """Truth-based figures of a trial, taken at every search tick: the horizontal path flown, the
    path until first within ``REACH_RADIUS_M`` of the source, the wind error, the track once per second."""

    def __init__(self, sim: Simulation, src: np.ndarray, rate_hz: float, keep_track: bool,
                 vehicle: LockstepVehicle) -> None:  # fmt: skip
        self.sim, self.src, self.keep_track, self.vehicle = sim, src, keep_track, vehicle
        self.wind_sq = np.zeros(3)
        self.wind_n = 0
        self.every = round(rate_hz)
        self.path = 0.0
        self.reach_path = math.nan
        self.prev: np.ndarray | None = None
        self.path_t: list[float] = []  # path flown so far at each tick, for the verification records
        self.path_m: list[float] = []
        self.track: list[list[float]] = []

    def tick(self, t: float) -> None:
        pos = self.sim.position
        if self.prev is not None:
            self.path += float(np.hypot(*(pos[0:2] - self.prev[0:2])))
        self.prev = pos
        self.path_t.append(t)
        self.path_m.append(self.path)
        if math.isnan(self.reach_path) and float(np.hypot(*(pos[0:2] - self.src[0:2]))) <= REACH_RADIUS_M:
            self.reach_path = self.path
        info = self.vehicle.wind_info
        if info is not None:
            self.wind_sq += (info.wind_ned - self.sim.wind_at_vehicle) ** 2
            self.wind_n += 1

    def wind_rmse(self) -> list[float]:
        """RMSE [m/s] N, E, D of the strategy's wind against the truth over the search ticks (nan if none)."""
        if self.wind_n == 0:
            return [math.nan] * 3
        return [round(float(v), 4) for v in np.sqrt(self.wind_sq / self.wind_n)]

    def every_tick(self, t: float) -> None:
        """The track, once per second from the first tick (take-off included)."""
        if self.keep_track and round(t * self.every) % self.every == 0:
            self.track.append([round(t, 2), *(round(float(v), 2) for v in self.sim.position)])


def _memory(strat: object) -> tuple[int, float]:
    """(detections, hit rate at the last candidate) of a strategy that keeps a detection memory
    (the bio-inspired ones do; the Strategy interface does not require it): (0, nan) otherwise."""
    mem = getattr(strat, "memory", None)
    if mem is None:
        return 0, math.nan
    return int(mem.n_detect), float(mem.hit_rate_at_last)


def _verification_records(strat: object, src: np.ndarray, t_end: float, path_t: list[float], path_m: list[float]
                          ) -> list[dict]:
    """The strategy's verification sweeps scored against the true source (see TrialResult)."""
    out = []
    for v in getattr(strat, "verifications", []):
        t1 = v.end(t_end)
        p0, p1 = np.interp([v.t_start, t1], path_t, path_m) if path_t else (0.0, 0.0)
        out.append({"t_start_s": round(v.t_start, 2), "duration_s": round(t1 - v.t_start, 2),
                    "path_m": round(float(p1 - p0), 2), "outcome": v.outcome,
                    "candidate_error_m": round(float(np.hypot(*(np.asarray(v.candidate_ne) - src[0:2]))), 2)})
    return out
