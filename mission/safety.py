"""Safety supervisor of a search mission flown through an autopilot (the MAVSDK runner).

Pure, synchronous checks with no I/O; the runner calls them and acts (hold, then land). Every
abort is a :class:`Abort` with a short ``cause`` code (for the JSON summary and tests) and one
human-readable line.

- **Geofence box and altitude limits** (:class:`SafetyLimits`, NED metres relative to home,
  altitudes above home): every setpoint is clamped into the box shrunk by ``margin_m`` and into
  the altitude band (:meth:`Supervisor.clamp`), so the mission never *commands* a point
  outside; if the vehicle is nevertheless outside the box by more than ``breach_tolerance_m``
  (wind gust, bad setpoint tracking), :meth:`Supervisor.check_vehicle` aborts with
  ``geofence``.
- **Mission time limit**: vehicle (autopilot) seconds since the mission started (arming).
- **Link loss** (:class:`LinkWatchdog`): no telemetry for ``link_timeout_s`` wall-clock seconds.
  While the link is down the autopilot's own failsafes fly the vehicle (offboard loss: hold;
  data-link loss NAV_DLL_ACT: land); when the link comes back the runner holds and lands.
- **Estimator fault** (:class:`EstimatorWatch`): a non-finite wind or covariance, a burst of
  rejected inputs, a covariance blow-up after convergence, or no estimator input at all.
- **Offboard rejection**: the runner turns a MAVSDK ``OffboardError`` (or the vehicle leaving
  offboard on its own) into an ``offboard-rejected`` / ``offboard-lost`` abort.

Conventions: SI units, NED, wind = air-mass velocity NED.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from mission.obstacles import Obstacles
from mission.safety_route import BuildingGuard, GuardConfig

#: Abort causes, in the JSON summary's ``cause`` (plus "declared" for a normal end).
CAUSES = (
    "declared", "search-ended", "time-limit", "geofence", "link-lost", "estimator-fault", "offboard-rejected",
    "offboard-lost", "takeoff-failed", "landed", "interrupted", "crash",
)  # fmt: skip


@dataclass(frozen=True)
class Abort:
    """Why the mission stops early: ``cause`` (one of :data:`CAUSES`) and one line for people."""

    cause: str
    message: str

    def line(self) -> str:
        return f"ABORT ({self.cause}): {self.message}"


@dataclass(frozen=True)
class SafetyLimits:
    """Limits the mission never leaves (metres, NED, relative to home; altitudes above home).

    box_min_ned / box_max_ned: geofence box corners (north, east, down); down is redundant with
        the altitude band (the tighter of the two applies).
    min_altitude_m / max_altitude_m: altitude band of every setpoint while searching [m].
    time_limit_s: mission time limit, vehicle seconds from arming [s].
    margin_m: setpoints stay this far inside the box [m].
    breach_tolerance_m: the vehicle may be this far outside the box before the mission aborts [m].
    link_timeout_s: wall-clock seconds without telemetry that count as a link loss [s].
    """

    box_min_ned: tuple[float, float, float] = (-150.0, -150.0, -30.0)
    box_max_ned: tuple[float, float, float] = (150.0, 150.0, 0.0)
    min_altitude_m: float = 1.0
    max_altitude_m: float = 30.0
    time_limit_s: float = 300.0
    margin_m: float = 1.0
    breach_tolerance_m: float = 2.0
    link_timeout_s: float = 3.0

    def validate(self) -> None:
        lo, hi = np.asarray(self.box_min_ned, float), np.asarray(self.box_max_ned, float)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError("geofence box: expected six finite numbers N,E,D,N,E,D (m)")
        if np.any(hi[0:2] - lo[0:2] <= 2.0 * self.margin_m):
            raise ValueError(f"geofence box {tuple(lo)}..{tuple(hi)}: north/east extent must exceed twice the "
                             f"{self.margin_m} m margin")  # fmt: skip
        if not (0.0 < self.min_altitude_m < self.max_altitude_m):
            raise ValueError(f"altitude limits [{self.min_altitude_m}, {self.max_altitude_m}] m: need 0 < min < max")
        if not (math.isfinite(self.time_limit_s) and self.time_limit_s > 0):
            raise ValueError(f"time limit {self.time_limit_s} s: must be > 0")
        if not (math.isfinite(self.link_timeout_s) and self.link_timeout_s > 0):
            raise ValueError(f"link timeout {self.link_timeout_s} s: must be > 0")

    @staticmethod
    def box_from_text(text: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """``"N,E,D,N,E,D"`` (two opposite corners, m) to (min corner, max corner)."""
        try:
            v = [float(x) for x in text.split(",")]
        except ValueError:
            raise ValueError(f"--geofence {text!r}: expected N,E,D,N,E,D in metres") from None
        if len(v) != 6:
            raise ValueError(f"--geofence {text!r}: expected six numbers N,E,D,N,E,D, got {len(v)}")
        a, b = np.array(v[0:3]), np.array(v[3:6])
        return tuple(np.minimum(a, b).tolist()), tuple(np.maximum(a, b).tolist())


class Supervisor:
    """Applies :class:`SafetyLimits` around a home point (NED, m), and keeps setpoints out of the
    buildings of ``obstacles`` (:mod:`mission.obstacles`), if any: a setpoint a building blocks is
    flown around it (:class:`mission.safety_route.BuildingGuard`, tuned by ``guard``), and whatever
    is sent is then clamped so that its straight path stays ``obstacles.margin_m`` clear."""

    def __init__(self, limits: SafetyLimits, home_ned: np.ndarray, obstacles: Obstacles | None = None,
                 guard: GuardConfig | None = None) -> None:  # fmt: skip
        limits.validate()
        self.limits = limits
        self.obstacles = obstacles
        self.home = np.asarray(home_ned, dtype=float).copy()
        self.guard = BuildingGuard(obstacles, float(self.home[2]), guard) if obstacles is not None and len(obstacles) \
            else None  # fmt: skip
        m = limits.margin_m
        lo = self.home + np.asarray(limits.box_min_ned, float)
        hi = self.home + np.asarray(limits.box_max_ned, float)
        self.box_lo, self.box_hi = lo, hi
        # Setpoint box: shrunk by the margin horizontally; vertically the tighter of the box
        # and the altitude band (down = home_down - altitude).
        self.sp_lo = np.array([lo[0] + m, lo[1] + m, max(lo[2], self.home[2] - limits.max_altitude_m)])
        self.sp_hi = np.array([hi[0] - m, hi[1] - m, min(hi[2], self.home[2] - limits.min_altitude_m)])
        if self.sp_lo[2] > self.sp_hi[2]:
            raise ValueError("geofence box and altitude limits leave no altitude to fly at")
        self.clamped = 0  # setpoints that had to be clamped

    def clamp(self, pos: np.ndarray | None, vel: np.ndarray | None, current: np.ndarray | None = None,
              current_vel: np.ndarray | None = None) -> tuple[np.ndarray | None, np.ndarray | None]:  # fmt: skip
        """A setpoint inside the limits: position clamped into the setpoint box; velocity
        components that point out of the box at its boundary zeroed (m, m/s, NED). For a
        velocity-only setpoint the boundary test uses ``current`` (the vehicle position). Among
        buildings (``current`` needed; ``current_vel``, the vehicle's velocity, lengthens the look
        ahead) a blocked setpoint is replaced by a detour's, then clamped clear of them."""
        hit = False
        if self.guard is not None and current is not None:
            pos, vel, hit = self.guard.apply(pos, vel, np.asarray(current, float), current_vel)
        if pos is not None:
            p = np.clip(np.asarray(pos, float), self.sp_lo, self.sp_hi)
            hit = hit or bool(np.any(p != pos))
            pos = p
        if vel is not None:
            v = np.asarray(vel, float).copy()
            ref = pos if pos is not None else (None if current is None else np.asarray(current, float))
            if ref is not None:
                at_lo = ref <= self.sp_lo + 1e-9
                at_hi = ref >= self.sp_hi - 1e-9
                out = (at_lo & (v < 0)) | (at_hi & (v > 0))
                if np.any(out):
                    hit = True
                    v[out] = 0.0
            vel = v
        if self.obstacles is not None and len(self.obstacles) and current is not None:
            pos, vel, blocked = self._around_buildings(pos, vel, np.asarray(current, float))
            hit = hit or blocked
        if hit:
            self.clamped += 1
        return pos, vel

    #: A velocity-only setpoint is checked this far ahead (s of flight at that velocity).
    LOOK_AHEAD_S = 2.0

    def _around_buildings(self, pos: np.ndarray | None, vel: np.ndarray | None, current: np.ndarray
                          ) -> tuple[np.ndarray | None, np.ndarray | None, bool]:  # fmt: skip
        """A position target moved back along the path from the vehicle so it stays clear of every
        building; a velocity that would carry the vehicle into one within LOOK_AHEAD_S stopped."""
        obs = self.obstacles
        assert obs is not None
        if pos is not None:
            safe = obs.clamp(current, pos, float(self.home[2]))
            if np.any(safe != pos):
                v = None if vel is None else np.where(np.arange(3) < 2, 0.0, vel)
                return safe, v, True
            return pos, vel, False
        if vel is not None:
            ahead = current + self.LOOK_AHEAD_S * np.asarray(vel, float)
            if np.any(obs.clamp(current, ahead, float(self.home[2])) != ahead):
                return None, np.array([0.0, 0.0, float(vel[2])]), True
        return pos, vel, False

    def altitude_target(self, altitude_m: float) -> float:
        """A requested altitude above home clamped into the band the setpoints may use [m]."""
        return float(np.clip(altitude_m, self.home[2] - self.sp_hi[2], self.home[2] - self.sp_lo[2]))

    def check_vehicle(self, pos: np.ndarray) -> Abort | None:
        """``geofence`` if the vehicle is outside the box (or above the ceiling) by more than the tolerance."""
        p = np.asarray(pos, float)
        tol = self.limits.breach_tolerance_m
        below_box = p < self.box_lo - tol
        above_box = p > self.box_hi + tol
        ceiling = self.home[2] - self.limits.max_altitude_m - tol
        if np.any(below_box[0:2]) or np.any(above_box[0:2]) or p[2] < max(self.box_lo[2] - tol, ceiling):
            rel = p - self.home
            return Abort("geofence", f"vehicle outside the geofence box / altitude limit at N {rel[0]:.1f} "
                         f"E {rel[1]:.1f} m, altitude {-rel[2]:.1f} m (relative to home)")  # fmt: skip
        return None

    def check_time(self, mission_t_s: float) -> Abort | None:
        """``time-limit`` once ``mission_t_s`` (vehicle seconds since arming) reaches the limit."""
        if mission_t_s >= self.limits.time_limit_s:
            return Abort("time-limit", f"mission time limit of {self.limits.time_limit_s:g} s reached")
        return None


class LinkWatchdog:
    """No telemetry for ``timeout_s`` (wall clock, s) = link lost. Feed it every message's arrival."""

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = float(timeout_s)
        self.last = -math.inf

    def feed(self, now: float) -> None:
        self.last = now

    def silent_s(self, now: float) -> float:
        return now - self.last

    def check(self, now: float) -> Abort | None:
        s = self.silent_s(now)
        if s > self.timeout_s:
            return Abort("link-lost", f"no telemetry for {s:.1f} s (limit {self.timeout_s:g} s): the autopilot's "
                         "own failsafe flies the vehicle (offboard loss: hold; data-link loss: land)")  # fmt: skip
        return None


class EstimatorWatch:
    """Faults of the live wind estimator, checked once per strategy tick.

    Args:
        max_sigma_m_s: horizontal 1-sigma above which the estimate, once converged, has blown up [m/s].
        burst: rejected inputs within ``window_s`` of vehicle time that count as a burst.
        input_timeout_s: vehicle seconds without an accepted IMU sample (after the first) = fault, counted
            on the estimator's own clock (the newest telemetry it has processed): a worker that lags behind
            the telemetry on a busy machine has not lost its input.
        max_lag_s: vehicle seconds the estimator may lag behind the telemetry before that is a fault (its
            wind is then that old).
    """

    #: Rejections that are not faults: inputs that arrive before the filter has its first
    #: attitude and rotor speeds, and samples a link duplicated or reordered (the filter already has
    #: them or is past them; a stream that only repeats itself ends in "no IMU sample" below).
    BENIGN = frozenset({"imu:not_ready", "gnss:not_ready", "gnss:stale", "imu:older_than_filter",
                        *(f"{s}:duplicate_or_out_of_order" for s in ("imu", "attitude", "rates", "rotors", "gnss"))})

    def __init__(self, max_sigma_m_s: float = 5.0, burst: int = 50, window_s: float = 2.0,
                 input_timeout_s: float = 2.0, max_lag_s: float = 10.0) -> None:  # fmt: skip
        self.max_sigma = max_sigma_m_s
        self.max_lag_s = max_lag_s
        self.burst = burst
        self.window_s = window_s
        self.input_timeout_s = input_timeout_s
        self.converged = False
        self._hist: deque[tuple[float, int]] = deque()
        self._imu_t = math.nan
        self._imu_n = 0

    def check(self, t: float, wind: np.ndarray, cov: np.ndarray, rejected: dict[str, int],
              imu_accepted: int, t_processed: float | None = None) -> Abort | None:  # fmt: skip
        """``estimator-fault`` or None. ``t`` vehicle time (s), ``wind`` NED (m/s), ``cov`` (m/s)^2,
        ``rejected`` the estimator's rejection counters, ``imu_accepted`` its accepted IMU count,
        ``t_processed`` the newest vehicle time the estimator has processed (None: ``t``)."""
        tp = t if t_processed is None or not math.isfinite(t_processed) else min(t, t_processed)
        if t - tp > self.max_lag_s:
            return Abort("estimator-fault", f"the estimator is {t - tp:.1f} s of vehicle time behind the telemetry "
                         f"(limit {self.max_lag_s:g} s): the machine is too busy for this speed")  # fmt: skip
        if not (np.all(np.isfinite(wind)) and np.all(np.isfinite(cov))):
            return Abort("estimator-fault", "the wind estimate is not finite (NaN/inf)")
        sig_h = math.sqrt(max(float(cov[0, 0] + cov[1, 1]), 0.0))
        if sig_h < 0.5 * self.max_sigma:
            self.converged = True
        elif self.converged and sig_h > self.max_sigma:
            return Abort("estimator-fault", f"wind covariance blew up: horizontal 1-sigma {sig_h:.1f} m/s "
                         f"(limit {self.max_sigma:g} m/s)")  # fmt: skip
        n_bad = sum(v for k, v in rejected.items() if k not in self.BENIGN)
        self._hist.append((t, n_bad))
        while self._hist and self._hist[0][0] < t - self.window_s:
            self._hist.popleft()
        if n_bad - self._hist[0][1] >= self.burst:
            worst = max(((k, v) for k, v in rejected.items() if k not in self.BENIGN), key=lambda kv: kv[1])
            return Abort("estimator-fault", f"{n_bad - self._hist[0][1]} estimator inputs rejected within "
                         f"{self.window_s:g} s (most: {worst[0]})")  # fmt: skip
        if imu_accepted != self._imu_n:
            self._imu_n, self._imu_t = imu_accepted, tp
        elif self._imu_n > 0 and tp - self._imu_t > self.input_timeout_s:
            return Abort("estimator-fault", f"no IMU sample accepted by the estimator for {tp - self._imu_t:.1f} s")
        return None
