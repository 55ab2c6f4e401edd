"""Infotaxis: Bayesian source-term estimation with information-driven moves.

The strategy keeps a posterior over the source (``mission.strategies.ste_filter``: particles
over horizontal position, height, effective release rate and plume direction offset), updates it
with every chemical reading -- hits *and* non-detections -- through the detection model of
``mission.strategies.ste_model`` (the mean Gaussian plume of the assumed stability class in the
filtered wind, with an intermittency model fitted to the plume's statistics), and flies where a
reading is expected to tell the most about the source:

- **Readings.** A hit is a reading above the detection limit that is not just the first-order
  sensor's decay (``PlumeMemory.add``); a miss is a reading below the limit; a decaying reading
  above the limit says nothing new and is skipped. Each is attributed to where the vehicle was
  ``sensor_lag_s`` earlier, at its height above home.
- **Moves** (infotaxis, Vergassola, Villermaux & Shraiman, Nature 445, 2007, with a short
  receding horizon): on the tick after each reading bin, ``plan_directions`` straight moves from
  the current position (the first along the current heading), as long as the distance to the
  posterior plus its credible radius (``plan_min_m`` to ``plan_horizon_m``), are scored by the
  largest expected information of ``plan_points`` readings along them -- the mutual information
  between a binary reading and the source, over ``plan_particles`` particles drawn from the
  posterior -- and the vehicle flies the best at ``speed_m_s``. Far from the source the most informative
  readings lie where the posterior is split between "the source is upwind of here" and "it is
  behind": the vehicle goes upwind along the plume; near it, around the source.
- **Declaration.** The ``credible_level`` (90 %) credible region is a disc whose centre is moved
  from the posterior mean toward the mode (``SourcePosterior.credible_disc``). When the
  posterior probability that the source lies within ``success_radius_m`` (3 m) of that centre --
  the confidence -- reaches ``declare_confidence`` (0.9), and the disc's radius is at most
  ``declare_radius_m``, both held for ``declare_hold_s`` (the posterior near a source swings; one
  crossing is a weak reason to stop), the centre is declared with that radius and that
  confidence. The vehicle flies over the point, descends and stops, as the other strategies do.
- **Free ticks** (neither a posterior update nor a move choice) weigh the particles redrawn at the
  last resampling against the reading history (``SourcePosterior.weigh_step``).
- Above a wind direction spread of ``spread_reference_deg`` (12 deg) the likelihood widens with the
  measured spread of the wind direction (``mission.strategies.ste_adapt``).

Without wind (``none``): the plume direction is a posterior dimension with a uniform prior (any
direction), the speed ``assumed_wind_m_s``; the hits themselves must then tell the direction. Such a
posterior's confidence is not calibrated (its direction collapses onto the first hits: open-field,
evaluation seeds, 85 % of declarations within 3 m at a stated 0.95), so it searches without declaring
unless ``declare_without_wind`` is 1, and says so.

Among buildings (``plume_model = "urban"``, ``mission/strategy_files/urban.toml``): the likelihood
follows backward paths through the urban diagnostic wind of the buildings the mission knows,
solved for the estimated inflow at the first usable wind (``ste_urban``, ``ste_urban_field``);
candidate points inside a building are no candidates and the chosen goal is reached along the
shortest route around the buildings (``ste_city``). When the urban model cannot be had (no usable
wind, a layout that makes no scene, readings from inside a footprint) the strategy says so,
weighs with the open-field plume and does not declare: among buildings that plume is known to put
the source in a lee (0 of 50 in paper-s4), a confidence from it would not be honest.

Frames and units: NED, SI; headings in rad (0 = north, clockwise); heights above home.
"""

from __future__ import annotations

import math
from concurrent.futures import Executor
from dataclasses import replace

import numpy as np

from mission.obstacles import Obstacles
from mission.strategies.base import Observation, Setpoint, WindInfo, heading_of, heading_vec
from mission.strategies.common import BaseStrategy
from mission.strategies.infotaxis_display import PosteriorDisplay
from mission.strategies.params import InfotaxisParams
from mission.strategies.ste_adapt import DirectionSpread, adapted_likelihood, mismatch_factor
from mission.strategies.ste_city import CitySupport
from mission.strategies.ste_filter import PriorBox, SourcePosterior
from mission.strategies.ste_model import model_constants, set_meander
from mission.strategies.ste_urban import UrbanModel
from mission.strategies.ste_urban_field import uniform_plane

#: Time constant of the wind-speed average the plume model uses [s].
SPEED_TAU_S = 10.0
#: Time constant of the altitude average the readings are placed at [s].
ALTITUDE_TAU_S = 2.0
#: Score bonus of continuing the current heading (fraction): keeps the vehicle from dithering
#: between moves of nearly equal value.
KEEP_HEADING_BONUS = 0.1
#: Urban model: a chosen goal is flown to (around the buildings) for up to GOAL_COMMIT_S [s] or
#: until within GOAL_REACHED_M [m] before the next move choice (development seed 101 of paper-s4: a
#: choice every bin dithered between two points 6 m either side of the vehicle for 240 s).
GOAL_COMMIT_S = 4.0
GOAL_REACHED_M = 1.5
#: Redrawn particles weighed against the reading history per free tick (``SourcePosterior.weigh_step``):
#: about 3 ms of CPU with 600 readings (300 s). The cost is particles x readings, so past
#: ``WEIGH_BUDGET`` readings-particles the tick weighs fewer: a mission longer than 300 s keeps the
#: tick's CPU bounded and takes more ticks to weigh the same particles.
WEIGH_PER_TICK = 40
WEIGH_BUDGET = WEIGH_PER_TICK * 600


def weigh_count(readings: int) -> int:
    """Particles to weigh on a free tick with ``readings`` readings in the history: ``WEIGH_PER_TICK``,
    fewer once particles x readings would pass ``WEIGH_BUDGET`` (at least 1)."""
    return max(1, min(WEIGH_PER_TICK, WEIGH_BUDGET // max(1, readings)))


#: Whether this process has run the numba kernels once (``warm_kernels``).
_warm = False


def warm_kernels(params: InfotaxisParams) -> None:
    """Run every numba kernel the strategy uses once, on a throwaway strategy with few particles,
    so that their first calls -- loading the machine code from numba's on-disk cache, or compiling
    it on a fresh install -- happen in ``reset`` (before arming), not in the first offboard ticks.
    Measured (``benchmarks/infotaxis_speed.py --first-calls``, quiet machine, warm disk cache): the
    first tick 0.20-0.23 s and the first 60 ticks 0.27-0.30 s without it, 5 ms and 0.06 s with it
    (``reset`` then takes 0.21-0.24 s); right after the cache was rewritten, on a busy machine, the
    first move choice and update took 0.9 + 0.4 s. A real autopilot leaves offboard after 1 s without
    a setpoint (PX4's COM_OF_LOSS_T), the SITL at speed 5 in the tests after 1 s of wall clock.
    Once per process."""
    global _warm
    if _warm:
        return
    _warm = True
    s = Infotaxis()
    s.reset(np.zeros(3), replace(params, n_particles=100, plan_particles=10, declare_hold_s=0.0), seed=0)
    wind = WindInfo(wind_ned=np.array([-4.0, 0.0, 0.0]), cov_ned=None, upwind_rad=0.0)
    if params.plume_model == "urban":  # the urban kernels too, on a slice without buildings
        s._init_prior(Observation(t=0.0, position_ned=np.zeros(3), velocity_ned=np.zeros(3), chem_mg_m3=0.0,
                                  detected=False, chem_new=False, wind=wind))
        s.post.set_urban(UrbanModel(uniform_plane((-4.0, 0.0), (-100.0, 100.0, -100.0, 100.0)), 3.0, 30.0))
    for k in range(40):  # hits, then misses: updates, a resampling and its weighing, moves, the disc
        c = 1.0 if (k < 30 and k % 2 == 0) else 0.0
        s.update(Observation(t=0.1 * k, position_ned=np.array([0.0, 0.0, -params.altitude_m]), velocity_ned=np.zeros(3),
                             chem_mg_m3=c, detected=c > 0.0, chem_new=True, wind=wind))
    s.posterior_map()


class Infotaxis(BaseStrategy, PosteriorDisplay):
    """Source-term estimation (particle posterior) + infotaxis moves + credible-region declaration."""

    name = "infotaxis"
    p: InfotaxisParams
    obstacles: Obstacles | None = None
    city: CitySupport | None = None
    field_solver: Executor | None = None
    windless: bool = False  # the prior was begun without wind information (no declaration by default)
    _windless_said: bool = False

    def set_obstacles(self, obstacles: Obstacles | None) -> None:
        """The buildings the mission knows (before ``reset``): the urban model's city."""
        self.obstacles = obstacles

    def set_field_solver(self, solver: Executor | None) -> None:
        """Where the urban wind field is solved off the tick (before ``reset``; ``ste_city``)."""
        self.field_solver = solver

    def pop_messages(self) -> list[str]:
        """Lines for the mission log since the last call (the urban model's state, bad readings)."""
        out: list[str] = []
        bad = getattr(getattr(self, "memory", None), "bad_readings", 0)
        if bad and not getattr(self, "_bad_said", False):
            self._bad_said = True
            out.append(f"{bad} detection(s) with a NaN or negative concentration ignored (counted as no reading)")
        if self.windless and not self.p.declare_without_wind and not self._windless_said:
            self._windless_said = True
            out.append("no wind information when the search began: a posterior without it is over-confident, so "
                       "the search goes on without declaring (declare_without_wind = 1 declares anyway)")
        if self.city is not None:
            out, self.city.messages = out + self.city.messages, []
        return out

    def reset(self, start_ned: np.ndarray, params: InfotaxisParams, seed: int = 0) -> None:  # type: ignore[override]
        warm_kernels(params)
        super().reset(start_ned, params, seed)
        p = params
        mc = model_constants(p.stability, p.source_radius_m, p.intermittency_length_m, p.detection_limit_mg_m3,
                             p.false_alarm, p.upwind_reach_m, p.meander_fraction,
                             math.radians(p.meander_deg))
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x1F07A5]))
        self.post = SourcePosterior(p.n_particles, mc, p.tempering, p.jitter, self.rng, int(p.meander_nodes),
                                    p.meander_window_s, math.exp(-p.bin_s / p.persistence_s), p.rejuvenate,
                                    (p.rejuvenate_along_m, p.rejuvenate_across_m), bool(p.rejuvenate_weighed))
        self.speed = math.nan
        self.heading: float | None = None
        self.credible_radius = math.nan
        self.n_hits = 0
        self.n_misses = 0
        self.last_info = 0.0
        self.diag: dict[str, float] = {}
        self._bin: list[float] = []  # t0, sums of north, east, readings; of north, east, readings of hits
        self.alt = math.nan
        self._plan_due = False
        self._disc_at = -1
        self._center = np.zeros(2)
        self.spread = DirectionSpread(p.spread_tau_s, p.min_wind_m_s)
        self.mismatch = 1.0
        self._sure_since = math.nan
        self._sure_at = np.zeros(2)
        self.windless, self._windless_said = False, False
        self.city = None if p.plume_model != "urban" else CitySupport(
            self.obstacles, p.urban_cell_m, p.urban_path_step_m, p.urban_path_length_m, p.urban_stall,
            p.urban_mix_rate, p.urban_probe_above_m, p.urban_probe_s, p.altitude_m)
        if self.city is not None:
            self.city.solver = self.field_solver
        self.inflow: np.ndarray | None = None
        self.goal: np.ndarray | None = None  # the point the last move choice aims at (urban model)
        self._goal_t = -math.inf

    # ------------------------------------------------------------------ wind
    def _plume_wind(self, obs: Observation, dt: float) -> tuple[float, float] | None:
        """(downwind heading [rad], speed [m/s]) of the mean plume, or None while the wind source
        has no usable direction yet; without wind information (``none``) north at the assumed
        speed (the posterior's direction offsets are then uniform)."""
        p = self.p
        w = obs.wind
        if w is None:
            return 0.0, p.assumed_wind_m_s
        if not math.isfinite(w.upwind_rad) or w.speed_m_s < p.min_wind_m_s:
            return None
        a = 1.0 if math.isnan(self.speed) else -math.expm1(-dt / SPEED_TAU_S)
        self.speed = w.speed_m_s if math.isnan(self.speed) else self.speed + a * (w.speed_m_s - self.speed)
        return w.upwind_rad + math.pi, max(self.speed, p.min_wind_m_s)

    def _init_prior(self, obs: Observation) -> None:
        p = self.p
        w = obs.wind
        sigma = None
        upwind = 0.0
        self.windless = w is None
        if w is not None:
            upwind = w.upwind_rad if self.inflow is None else heading_of(-self.inflow)
            sigma = math.hypot(math.radians(p.direction_sigma_deg), min(w.upwind_sigma_rad, math.radians(30.0)))
        pos = obs.position_ned[0:2]
        self.post.init_prior(PriorBox(
            origin_ne=(float(pos[0]), float(pos[1])), upwind_rad=upwind, ahead=p.prior_range_m, back=p.prior_back_m,
            half_width=p.prior_half_width_m, h_range=(p.source_height_min_m, p.source_height_max_m),
            q_range=(p.release_min_g_s, p.release_max_g_s), delta_sigma=sigma))
        if self.city is not None and self.inflow is not None:
            self.post.set_urban(self.city.build(self.inflow, p.altitude_m))

    @property
    def model_unusable(self) -> bool:
        """The urban model was asked for among buildings and could not be had: no declaration."""
        return self.city is not None and self.city.obstacles is not None and self.post.urban is None

    # ------------------------------------------------------------------ tick
    def update(self, obs: Observation) -> Setpoint:
        if self.p is None:
            raise RuntimeError(f"{self.name}: reset() must be called before update()")
        p = self.p
        dt = 1.0 / p.rate_hz if self.t_prev is None else max(obs.t - self.t_prev, 0.0)
        self.t_prev = obs.t
        hit = self.memory.add(obs)
        wind = self._plume_wind(obs, dt)
        if obs.wind is not None:
            self.spread.add(float(obs.wind.wind_ned[0]), float(obs.wind.wind_ned[1]), dt)
        u_vec = heading_vec(obs.wind.upwind_rad) if wind is not None and obs.wind is not None else heading_vec(0.0)
        if self.declared is not None:
            return self._descend(obs, u_vec)
        if wind is None:  # no usable wind direction yet: hold here (over the roofs while the inflow is measured,
            # not back at the search height: flipping between the two mid-climb tripped the live estimator's check)
            city = self.city
            alt = city.probe_height_m if city is not None and city.waiting(self.inflow, obs.t) else p.altitude_m
            return Setpoint(position_ned=self._carrot(obs, np.zeros(2), dt, alt), velocity_ned=np.zeros(3),
                            state="wait-wind")
        if self.city is not None and self.city.obstacles is not None and self.inflow is None:
            self.inflow = self.city.probe(obs.wind.wind_ned if obs.wind is not None else None,
                                          float(self.start[2] - obs.position_ned[2]), dt, obs.t)
        wait = None if self.city is None else self.city.waiting(self.inflow, obs.t)
        if wait is not None and self.city is not None:  # over the roofs: measure the inflow, solve the field
            return Setpoint(position_ned=self._carrot(obs, np.zeros(2), dt, self.city.probe_height_m),
                            velocity_ned=np.zeros(3), state=wait)
        if not self.post.ready:
            self._init_prior(obs)
        downwind, speed = wind
        # The move is chosen on the tick after a bin updated the posterior: the two costs fall on
        # different ticks (benchmarks/infotaxis_speed.py), the move 0.1 s later.
        replan = self.heading is None or self._plan_due
        self._plan_due = False
        if obs.chem_new and self._add_reading(obs, hit, downwind, speed):
            self._plan_due = True
        elif not replan:  # a tick without a posterior update or a move choice (an urban reading costs 2)
            self.post.weigh_step(weigh_count(len(self.post.history) * (1 if self.city is None else 2)))
        if self.post.version != self._disc_at:  # the posterior only changes with a bin
            self._disc_at = self.post.version
            self._center, self.credible_radius = self.post.credible_disc(p.credible_level)
            self.confidence = self.post.mass_within(self._center, p.success_radius_m)
        center = self._center
        if self._sure(obs.t, center):
            self._declare_posterior(obs.t, center)
            return self._descend(obs, u_vec)
        if replan:
            self._plan(obs, center, downwind, speed)
        heading = 0.0 if self.heading is None else self.heading  # _plan() has set it
        v_ne = self._speed(obs, center) * heading_vec(heading)
        pos_sp = self._carrot(obs, v_ne, dt, p.altitude_m)
        return Setpoint(position_ned=pos_sp, velocity_ned=np.array([v_ne[0], v_ne[1], 0.0]),
                        yaw_rad=heading_of(u_vec), state="search",
                        info={"credible_radius_m": self.credible_radius, "info_bits": self.last_info,
                              "ess": self.post.ess(), "mismatch": self.mismatch})

    def _add_reading(self, obs: Observation, hit: bool, downwind: float, speed: float) -> bool:
        """Put a new reading into the current bin; a full bin updates the posterior: a hit if any
        reading in it was a hit, placed at the mean position of its hit readings; else a miss
        (a reading that only decays is no hit: what arrives at the sensor then is below what a
        hit needs), placed at the mean position of the bin. Positions: where the vehicle was
        ``sensor_lag_s`` before each reading; height: the vehicle's, averaged over
        ``ALTITUDE_TAU_S`` (the navigation altitude is noisier than the flown one)."""
        p = self.p
        lag = obs.position_ned[0:2] - p.sensor_lag_s * obs.velocity_ned[0:2]
        alt = float(self.start[2] - obs.position_ned[2])
        a = 1.0 if math.isnan(self.alt) else -math.expm1(-1.0 / (p.rate_hz * ALTITUDE_TAU_S))
        self.alt = alt if math.isnan(self.alt) else self.alt + a * (alt - self.alt)
        b = self._bin
        if not b:
            b.extend([obs.t, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        b[1] += float(lag[0])
        b[2] += float(lag[1])
        b[3] += 1.0
        if hit:
            b[4] += float(lag[0])
            b[5] += float(lag[1])
            b[6] += 1.0
        if obs.t - b[0] < p.bin_s - 1e-6:
            return False
        self._adapt()
        if b[6] > 0.0:
            self.post.update(obs.t, b[4] / b[6], b[5] / b[6], self.alt, True, downwind, speed)
            self.n_hits += 1
        else:
            self.post.update(obs.t, b[1] / b[3], b[2] / b[3], self.alt, False, downwind, speed)
            self.n_misses += 1
        b.clear()
        if self.city is not None and self.post.urban is not None and not self.city.check_position(self.post.n_fallback):
            self.post.set_urban(None)
        return True

    def _adapt(self) -> None:
        """Widen the likelihood by the measured direction spread (``ste_adapt``): the tempering
        and the meander the next reading is weighed with."""
        p = self.p
        self.mismatch = mismatch_factor(self.spread.spread_rad, math.radians(p.spread_reference_deg))
        kappa, meander = adapted_likelihood(self.mismatch, p.tempering, math.radians(p.meander_deg),
                                            p.spread_tempering_power, p.spread_meander_power)
        self.post.kappa = kappa
        set_meander(self.post.mc, meander)

    def _speed(self, obs: Observation, center: np.ndarray) -> float:
        """Ground speed [m/s]: ``speed_m_s`` while the source is far or unknown, ``near_speed_m_s``
        once the posterior is within ``near_m`` of the vehicle and no wider than that: what the
        path costs is metres, and near a source a slower vehicle takes more readings per metre."""
        p = self.p
        d = float(np.hypot(*(center - obs.position_ned[0:2])))
        near = d <= p.near_m and self.credible_radius <= p.near_m
        return p.near_speed_m_s if near else p.speed_m_s

    def _plan(self, obs: Observation, center: np.ndarray, downwind: float, speed: float) -> None:
        """Choose the most informative move (module docstring): sets ``heading`` [rad].

        Each candidate heading is scored by the most informative single reading along it
        (Hutchinson, Liu & Chen, AutoSTE, score the end points of their moves the same way): a
        sum over the points would favour long runs through mildly informative far field over a
        short approach to where the posterior is. The horizon shrinks with the posterior: the
        distance to its mean plus its credible radius, between ``plan_min_m`` and
        ``plan_horizon_m``."""
        p = self.p
        pos = obs.position_ned[0:2]
        if (self.city is not None and self.goal is not None and obs.t - self._goal_t < GOAL_COMMIT_S
                and float(np.hypot(*(self.goal - pos))) > GOAL_REACHED_M):  # on the way to the last goal
            self.heading = self.city.heading_to(pos, self.goal, p.altitude_m)
            return
        k_dirs, n_pts = int(p.plan_directions), int(p.plan_points)
        h0 = heading_of(pos - self.start[0:2]) if self.heading is None else self.heading
        headings = h0 + 2.0 * math.pi * np.arange(k_dirs) / k_dirs
        horizon = float(np.hypot(*(center - pos))) + self.credible_radius
        horizon = min(max(horizon, p.plan_min_m), p.plan_horizon_m)
        dist = horizon * np.arange(1, n_pts + 1) / n_pts
        cx = (pos[0] + np.outer(np.cos(headings), dist)).ravel()
        cy = (pos[1] + np.outer(np.sin(headings), dist)).ravel()
        plan = self.post.planning_set(int(p.plan_particles))
        info, _ = self.post.information(cx, cy, p.altitude_m, downwind, speed, plan)
        if self.city is not None:  # no candidate readings inside a building
            info = np.where(self.city.free(cx, cy, p.altitude_m), info, -np.inf)
        score = info.reshape(k_dirs, n_pts).max(axis=1)
        # Moves that would leave the allowed range are not candidates.
        far = np.hypot(cx - self.start[0], cy - self.start[1]).reshape(k_dirs, n_pts)[:, -1] > p.max_range_m
        score[far] = -np.inf
        if self.heading is not None:
            score[0] *= 1.0 + KEEP_HEADING_BONUS
        k = int(np.argmax(score))
        self.last_scores = (headings, score)
        if not math.isfinite(score[k]):  # every move leaves the range: go home-ward
            self.heading = heading_of(self.start[0:2] - pos)
        elif self.city is not None:  # toward the best reading of that move, around the buildings
            j = k * n_pts + int(np.argmax(info[k * n_pts:(k + 1) * n_pts]))
            self.goal, self._goal_t = np.array([cx[j], cy[j]]), obs.t
            self.heading = self.city.heading_to(pos, self.goal, p.altitude_m)
        else:
            self.heading = float((headings[k] + math.pi) % (2.0 * math.pi) - math.pi)
        self.last_info = float(score[k]) if math.isfinite(score[k]) else 0.0

    # ------------------------------------------------------------------ declaration
    def _sure(self, t: float, center: np.ndarray) -> bool:
        """The declaration test: the confidence at least ``declare_confidence`` and the disc at most
        ``declare_radius_m``, held for ``declare_hold_s`` [s] with the centre within
        ``declare_radius_m`` of where it first was."""
        p = self.p
        if (self.confidence < p.declare_confidence or self.credible_radius > p.declare_radius_m or self.model_unusable
                or (self.windless and not p.declare_without_wind)
                or (self.city is not None and p.urban_decline_dead_air and not self.city.usable_at(center))):
            self._sure_since = math.nan
            return False
        if math.isnan(self._sure_since) or float(np.hypot(*(center - self._sure_at))) > p.declare_radius_m:
            self._sure_since, self._sure_at = t, center.copy()
        return t - self._sure_since >= p.declare_hold_s - 1e-9

    def _declare_posterior(self, t: float, center: np.ndarray) -> None:
        self.declared = np.array([center[0], center[1], self.start[2] - self.post.mean_height()])
        self.t_declared = t
        self.diag = {"credible_radius_m": self.credible_radius, "n_hits": float(self.n_hits),
                     "n_misses": float(self.n_misses), "n_resamples": float(self.post.n_resamples),
                     "source_height_m": self.post.mean_height(),
                     "release_g_s": float(10.0 ** (self.post.w @ self.post.lq)),
                     "direction_spread_deg": math.degrees(self.spread.spread_rad), "mismatch": self.mismatch}

    def _descend(self, obs: Observation, u: np.ndarray) -> Setpoint:
        sp = super()._descend(obs, u)
        sp.credible_radius_m = self.credible_radius
        return sp
