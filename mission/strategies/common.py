"""Machinery shared by the strategies: the upwind axis, crosswind sweeps, the "plume ended"
declaration rule and the final descent (the plume memory is in plume_memory.py).

Frames and units: NED, SI; headings in rad (0 = north, clockwise). Horizontal vectors are
(north, east). ``u`` is the unit upwind vector (toward where the wind comes from), ``n`` the
unit crosswind vector 90 deg to its right (u rotated clockwise: n = (-u_e, u_n)).

Declaration rule (all strategies; details in ``mission/README.md``): the candidate source is
the most-upwind hit (along the current upwind axis), each hit placed where the vehicle was
``sensor_lag_s`` before the reading (the sensor's first-order lag would otherwise push the
candidate upwind). When the plume has been lost for ``lost_s`` with the vehicle at least
``overshoot_m`` upwind of the candidate, a crosswind verification sweep flies upwind of it; a
hit interrupts it (the plume goes on), a sweep that finds nothing is a *verified end*. The
candidate is declared after ``confirmations`` verified ends at the same place if it is
supported: ``min_hits_near`` hits within 5 m and hits reaching ``min_followed_m`` downwind of
it (a source ends a plume that was followed). Fallback: lost for ``declare_after_s`` after a
verified end at a supported candidate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mission.strategies.base import Observation, Setpoint, heading_of, heading_vec
from mission.strategies.params import CommonParams
from mission.strategies.plume_memory import PlumeMemory

#: Two losses whose candidates lie within this distance count as the same plume end [m].
REPEAT_TOL_M = 3.0
#: Largest distance of the position setpoint from the observed position [m].
CARROT_MAX_M = 2.0


def crosswind(u: np.ndarray) -> np.ndarray:
    """Unit crosswind vector 90 deg clockwise (to the right) of the unit upwind vector ``u``."""
    return np.array([-u[1], u[0]])


class UpwindAxis:
    """The upwind heading the strategy works with: the filtered wind direction when a wind
    source gives one; without wind (``none`` mode, pure chemotaxis), an estimate from the
    concentration gradient, starting from ``initial_heading_deg`` (or a seeded draw)."""

    def __init__(self, params: CommonParams, seed: int) -> None:
        self.p = params
        if math.isnan(params.initial_heading_deg):
            rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xA215]))
            self.heading = float(rng.uniform(-math.pi, math.pi))
        else:
            self.heading = math.radians(params.initial_heading_deg)
        self.source = "initial"

    def update(self, obs: Observation, memory: PlumeMemory, dt: float) -> np.ndarray:
        """Current unit upwind vector (north, east)."""
        w = obs.wind
        if w is not None and w.speed_m_s >= self.p.min_wind_m_s and math.isfinite(w.upwind_rad):
            self.heading = w.upwind_rad
            self.source = "wind"
        elif w is None:
            g = memory.gradient_heading()
            if g is not None:
                # Turn toward the gradient at a bounded rate (the gradient estimate is noisy).
                a = min(1.0, dt / 5.0)
                v = (1 - a) * heading_vec(self.heading) + a * heading_vec(g)
                self.heading = heading_of(v)
                self.source = "gradient"
        return heading_vec(self.heading)


class Sweep:
    """Crosswind sweeps of growing half-width about a world reference point: the moth's cast,
    the zig-zag's lost search and the verification sweep.

    The sweep is centred on ``ref`` (north, east, m): crosswind legs to ``half`` on either
    side of it, the along-wind target ``along0`` m upwind of it (negative: downwind), drifting
    downwind at ``drift`` m/s -- the plume is downwind of its source, so backing off widens the
    cross-section swept. Offsets are taken along the *current* axis (``u``, ``n``), so when
    the wind direction turns the pattern turns about ``ref``, as the plume near it does. (Why
    not scalar coordinates about the start: the upwind axis of the estimated wind swings by
    tens of degrees, and 60 m from the start a 10 deg turn would move such a sweep 10 m.)
    """

    def __init__(self, t0: float, ref_ne: np.ndarray, along0: float, half_width: float, growth: float,
                 max_half_width: float, direction: float, drift: float) -> None:
        self.t0 = t0
        self.ref = np.asarray(ref_ne, dtype=float).copy()
        self.along0 = along0
        self.half = half_width
        self.growth = growth
        self.max_half = max_half_width
        self.dir = 1.0 if direction >= 0 else -1.0
        self.drift = drift
        self.n_legs = 0

    def velocity(self, t: float, pos: np.ndarray, u: np.ndarray, n: np.ndarray, speed: float) -> np.ndarray:
        """Horizontal velocity (north, east), m/s; flips at each end and grows the width."""
        d = pos - self.ref
        c_now = float(d @ n)
        a_now = float(d @ u)
        target = self.dir * self.half
        if (target - c_now) * self.dir <= 0.0:
            self.dir = -self.dir
            self.n_legs += 1
            if self.n_legs % 2 == 0:  # a full sweep (both sides) without finding anything
                self.half = min(self.half * self.growth, self.max_half)
        a_target = self.along0 - self.drift * (t - self.t0)
        v_along = float(np.clip(0.8 * (a_target - a_now), -0.8 * speed, 0.8 * speed))
        v_cross = math.sqrt(max(speed * speed - v_along * v_along, 0.0))
        return self.dir * v_cross * n + v_along * u

    @classmethod
    def start(cls, t: float, pos: np.ndarray, u: np.ndarray, n: np.ndarray, memory: PlumeMemory,
              half_width: float, growth: float, max_half_width: float, drift: float, back_m: float) -> Sweep:
        """A lost search from the current situation: centred on the plume centreline (or here),
        ``back_m`` downwind of the last detection (or here), first toward the centreline."""
        c_now = float(pos @ n)
        center = memory.centerline(t, n)
        center = c_now if center is None else center
        if memory.det_pos:
            ref = float(memory.det_pos[-1] @ u) * u + center * n
            along0 = -back_m
        else:
            ref = pos.copy()
            along0 = 0.0
        direction = 1.0 if center >= c_now else -1.0
        return cls(t, ref, along0, half_width, growth, max_half_width, direction, drift)


@dataclass
class Verification:
    """One verification sweep, for diagnostics: when it started (s), the candidate it tested
    (north, east, m) and how it ended: ``"verified"`` (no hit: a verified end),
    ``"interrupted"`` (a hit: the plume goes on upwind) or ``""`` while it runs."""

    t_start: float
    candidate_ne: tuple[float, float]
    t_end: float = math.nan
    outcome: str = ""

    def end(self, t_now: float) -> float:
        """When it ended (s), or ``t_now`` while it still runs."""
        return self.t_end if self.outcome else t_now


class BaseStrategy:
    """Common frame of the strategies: altitude hold, axis, memory, declaration, descent.

    Subclasses implement :meth:`_search` (horizontal velocity and state name while searching).
    """

    name = "base"
    #: The parameters, set by :meth:`reset` (subclasses narrow the type to their own params);
    #: :meth:`update` refuses to run before it.
    p: CommonParams

    def reset(self, start_ned: np.ndarray, params: CommonParams, seed: int = 0) -> None:
        self.p = params
        self.start = np.asarray(start_ned, dtype=float).copy()
        self.memory = PlumeMemory(params)
        self.axis = UpwindAxis(params, seed)
        self.t_prev: float | None = None
        self.declared: np.ndarray | None = None
        self.t_declared = math.nan
        self.confidence = 0.0
        self.t_over = math.nan  # time the descent point was reached
        self.verify: Sweep | None = None  # the verification sweep upwind of a candidate, when active
        self.verify_cand: np.ndarray | None = None
        self.verified: list[np.ndarray] = []  # candidate (north, east, m) of every verified end
        self.n_verify_aborted = 0
        self.verifications: list[Verification] = []  # every verification sweep, for diagnostics
        self.verify_spread = 0.0
        self._verify_armed = True
        self.carrot: np.ndarray | None = None
        self.sweep: Sweep | None = None  # the lost search, when active
        self.mode = "acquire"
        self._reset()

    def _reset(self) -> None:
        """Subclass state."""

    def _search(self, obs: Observation, u: np.ndarray, n: np.ndarray, new_det: bool, dt: float
                ) -> tuple[np.ndarray, str]:
        raise NotImplementedError

    # ------------------------------------------------------------------ helpers
    def _verify_due(self, t: float, pos_ne: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        """The candidate to verify now, or None: there is a candidate, the plume has been lost
        for ``lost_s``, the vehicle is at least ``overshoot_m`` upwind of the candidate, and it
        has detected something since the last verification (a verification that found
        nothing needs a re-acquisition before the next one)."""
        m = self.memory
        p = self.p
        if not self._verify_armed or m.since_detect(t) < p.lost_s:
            return None
        cand = m.most_upwind(u)
        if cand is None or float((pos_ne - cand) @ u) < p.overshoot_m:
            return None
        return cand

    def _verify_step(self, obs: Observation, u: np.ndarray, n: np.ndarray, new_det: bool) -> np.ndarray | None:
        """One tick of the verification sweep; its velocity (north, east) m/s, or None when it
        is over (aborted by a hit, or complete: then counted and possibly declared)."""
        p = self.p
        # update() calls this only while a verification runs; _start_verify sets both.
        assert self.verify is not None and self.verify_cand is not None
        if new_det:
            # Plume upwind of the candidate: not the end; the strategy takes over (surge). This
            # hit is a candidate however weak (else the next verification would start from the
            # same place and be interrupted by the same weak plume edge for ever).
            self.memory.det_eligible[-1] = True
            self.verify = None
            self.n_verify_aborted += 1
            self._end_verification(obs.t, "interrupted")
            return None
        pos = obs.position_ned[0:2]
        v = self.verify.velocity(obs.t, pos, u, n, p.verify_speed_m_s)
        if self.verify.n_legs < p.verify_legs:
            return v
        # Both sides covered without a single hit: one verified end at this candidate.
        cand = self.verify_cand
        self.verify = None
        self.verified.append(cand.copy())
        self._end_verification(obs.t, "verified")
        n_same = self._n_verified_at(cand, u)
        if n_same >= self._confirmations_needed() and self._supported(cand, u):
            self._declare(obs.t, cand, repeat=n_same >= 2)
        self._after_verify()
        return None

    def _n_verified_at(self, cand: np.ndarray, u: np.ndarray) -> int:
        """Verified ends at the same plume end as ``cand``: within ``REPEAT_TOL_M`` of it along
        the current upwind axis (compared as differences, so a turning axis does not move
        candidates tens of metres from the start)."""
        return sum(abs(float((cand - c) @ u)) <= REPEAT_TOL_M for c in self.verified)

    def _supported(self, cand: np.ndarray, u: np.ndarray) -> bool:
        """Enough hits within 5 m of ``cand`` (``min_hits_near``): the plume just downwind of a
        source is continuous, so the surges and re-acquisitions there collect many hits; a
        far-field "end" (a gap, a meander, the plume above or below the sensor) has few. And
        the hits reach at least ``min_followed_m`` downwind of ``cand``: a source is the upwind
        end of a plume that was followed, not a burst of far-field puffs met in passing (one
        such burst gives 20-30 hits within 5 m in 3-4 s)."""
        m = self.memory
        if m.n_near(cand, 5.0) < self.p.min_hits_near:
            return False
        return float(np.max((cand - np.asarray(m.det_pos)) @ u)) >= self.p.min_followed_m

    def _confirmations_needed(self) -> int:
        """Verified ends at the same place needed to declare (``confirmations``)."""
        return int(self.p.confirmations)

    def _after_verify(self) -> None:
        """A verification found nothing: the lost search restarts from the last hit
        (re-acquire, then verify again)."""
        self.sweep = None

    def _lost_search(self, obs: Observation, u: np.ndarray, n: np.ndarray, lost_state: str, half_width: float,
                     growth: float, max_half_width: float, drift: float, back_m: float) -> tuple[np.ndarray, str]:
        """Velocity (north, east, m/s) and state of the lost search: crosswind sweeps about
        the plume centreline (see :class:`Sweep`), started at the first call after the plume
        was lost; the state is ``lost_state`` after a detection, ``acquire`` before any."""
        pos = obs.position_ned[0:2]
        if self.sweep is None:
            self.sweep = Sweep.start(obs.t, pos, u, n, self.memory, half_width, growth, max_half_width, drift, back_m)
            self.mode = lost_state if self.memory.n_detect > 0 else "acquire"
        return self.sweep.velocity(obs.t, pos, u, n, self.p.speed_m_s), self.mode

    def _start_verify(self, t: float, pos_ne: np.ndarray, u: np.ndarray, n: np.ndarray, cand: np.ndarray,
                      sigma_rad: float) -> None:
        """Start the verification sweep ``verify_offset_m`` upwind of ``cand``: crosswind, about
        the candidate, half-width ``verify_half_width_m`` widened by the direction uncertainty
        (the plume near a source follows the instantaneous wind)."""
        p = self.p
        # The local plume width: the crosswind spread of the recent hits (a few metres at a
        # source, wide in the meandering far field, where a narrow sweep would miss a plume
        # that has only swung aside).
        spread = self.memory.crosswind_spread(t, n, u, float(cand @ u))
        self.verify_spread = spread
        half = max(p.verify_half_width_m, 0.5 * spread + p.verify_margin_m)
        # Each earlier verified end at the same place widens the next sweep (a moth casts wider
        # and wider): at a source nothing is found however wide; a far-field plume that has
        # swung further aside than the first sweep reached is found by a later one.
        n_before = self._n_verified_at(cand, u)
        half *= p.verify_growth**n_before
        half = min(half + math.tan(min(sigma_rad, math.radians(45.0))) * p.verify_offset_m, p.verify_max_half_width_m)
        direction = 1.0 if float((cand - pos_ne) @ n) >= 0.0 else -1.0
        self.verify = Sweep(t, cand, p.verify_offset_m, half, 1.0, half, direction, 0.0)
        self.verify_cand = cand.copy()
        self._verify_armed = False
        self.verifications.append(Verification(t, (float(cand[0]), float(cand[1]))))

    def _end_verification(self, t: float, outcome: str) -> None:
        rec = self.verifications[-1]
        rec.t_end, rec.outcome = t, outcome

    def _check_timeout_declare(self, t: float, u: np.ndarray) -> bool:
        """Fallback: lost for ``declare_after_s`` after a verified end at the current candidate
        (the lost search could not re-acquire the plume downwind of it): declare it."""
        m = self.memory
        if self.verify is not None or m.since_detect(t) < self.p.declare_after_s:
            return False
        cand = m.most_upwind(u)
        if cand is None:
            return False
        if self._n_verified_at(cand, u) > 0 and self._supported(cand, u):
            return self._declare(t, cand, repeat=False)
        return False

    def _declare(self, t: float, cand: np.ndarray, repeat: bool) -> bool:
        z_src = self.start[2] - self.p.descend_altitude_m
        self.declared = np.array([cand[0], cand[1], z_src])
        self.t_declared = t
        n = self.memory.n_near(cand, 5.0)
        # Confidence: support of the candidate by nearby detections, and whether the plume end
        # was confirmed by a second loss at the same place.
        self.confidence = float((1.0 - math.exp(-n / 10.0)) * (1.0 if repeat else 0.8))
        self.diag = {"peak_near": self.memory.peak_near(cand, 5.0),
                     "median_all": float(np.median(self.memory.all_values)), "repeat": float(repeat),
                     "spread": float(self.verify_spread), "n_verified": float(len(self.verified)),
                     "n_aborted": float(self.n_verify_aborted), "n_near": float(n),
                     "hit_rate": float(self.memory.hit_rate_at_last)}
        return True

    # ------------------------------------------------------------------ tick
    def update(self, obs: Observation) -> Setpoint:
        if getattr(self, "p", None) is None:
            raise RuntimeError(f"{self.name}: reset() must be called before update()")
        p = self.p
        dt = 1.0 / p.rate_hz if self.t_prev is None else max(obs.t - self.t_prev, 0.0)
        self.t_prev = obs.t
        new_det = self.memory.add(obs)
        u = self.axis.update(obs, self.memory, dt)
        n = crosswind(u)
        pos_ne = obs.position_ned[0:2]
        if new_det:
            self._verify_armed = True
        if self.declared is None:
            self._check_timeout_declare(obs.t, u)
        v_ne = None
        if self.declared is None and self.verify is None:
            cand = self._verify_due(obs.t, pos_ne, u)
            if cand is not None:
                sigma = obs.wind.upwind_sigma_rad if obs.wind is not None else math.radians(20.0)
                self._start_verify(obs.t, pos_ne, u, n, cand, sigma)
        if self.declared is None and self.verify is not None:
            v_ne = self._verify_step(obs, u, n, new_det)
            state = "verify"
        if self.declared is not None:
            return self._descend(obs, u)
        if v_ne is None:
            v_ne, state = self._search(obs, u, n, new_det, dt)
        pos_sp = self._carrot(obs, v_ne, dt, p.altitude_m)
        return Setpoint(position_ned=pos_sp, velocity_ned=np.array([v_ne[0], v_ne[1], 0.0]),
                        yaw_rad=heading_of(u), state=state,
                        info={"upwind_deg": math.degrees(heading_of(u)) % 360.0})

    def _carrot(self, obs: Observation, v_ne: np.ndarray, dt: float, altitude_m: float) -> np.ndarray:
        """Position setpoint (m, NED) moving with the commanded velocity.

        Why a position + velocity feed-forward pair rather than a bare velocity: the autopilot
        then holds altitude and track on its own navigation solution (no GNSS noise through
        this 10 Hz loop), as PX4 does with a position-velocity offboard setpoint. The carrot is
        kept within ``CARROT_MAX_M`` of the observed position so it cannot run away.
        """
        pos = obs.position_ned[0:2]
        if self.carrot is None:
            self.carrot = pos.copy()
        self.carrot = self.carrot + np.asarray(v_ne) * dt
        d = self.carrot - pos
        dist = float(np.hypot(d[0], d[1]))
        if dist > CARROT_MAX_M:
            self.carrot = pos + d * (CARROT_MAX_M / dist)
        return np.array([self.carrot[0], self.carrot[1], self.start[2] - altitude_m])

    def _descend(self, obs: Observation, u: np.ndarray) -> Setpoint:
        """Fly over the declared point, descend to ``descend_altitude_m``, hold, then done."""
        p = self.p
        assert self.declared is not None  # update() descends only once a source is declared
        d = self.declared[0:2] - obs.position_ned[0:2]
        dist = float(np.hypot(d[0], d[1]))
        over = dist < 1.0
        alt = p.descend_altitude_m if over else p.altitude_m
        pos = np.array([self.declared[0], self.declared[1], self.start[2] - alt])
        if over and math.isnan(self.t_over) and abs(obs.position_ned[2] - pos[2]) < 0.5:
            self.t_over = obs.t
        done = not math.isnan(self.t_over) and obs.t - self.t_over >= p.descend_hold_s
        return Setpoint(
            position_ned=pos, yaw_rad=heading_of(u), done=done,
            declared_source_ned=self.declared.copy(), confidence=self.confidence,
            state="done" if done else "descend", info={"t_declared": self.t_declared},
        )
