"""Safety of the identification flight on PX4: the checks, pure and synchronous (the adapter acts on them).

As the mission runner (:mod:`mission.safety`): a geofence box about the start (horizontal half-width
``fence_m``, altitude up to ``ceiling_m`` above home; :class:`mission.safety.Supervisor`) and, for the
manoeuvre, an altitude floor; then what an identification flight adds: the attitude beyond ``tilt_deg``
(a multisine on a badly tuned or overloaded vehicle), the motor outputs saturated for longer than
``saturation_s`` (the vehicle has no control authority left), and the link (no telemetry for
``link_timeout_s`` wall seconds) or offboard mode lost. Every check returns an
:class:`mission.safety.Abort` (``cause`` and one line) or None; the adapter then switches PX4 to HOLD and
lands. Units m, s (vehicle time unless said), deg on the options; NED relative to home.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mission.safety import Abort, SafetyLimits, Supervisor

#: Abort causes of an identification flight (the JSON's ``abort.cause``).
CAUSES = ("geofence", "floor", "attitude", "saturation", "link-lost", "offboard-lost", "command-failed",
          "interrupted", "stalled")  # fmt: skip


@dataclass(frozen=True)
class GuardLimits:
    """fence_m: half-width of the box about the start (m); floor_m / ceiling_m: altitude band above home
    during the manoeuvres (m); tilt_deg: largest tilt from level (deg); saturation_s: longest run of a motor
    output at either end of its range (s); link_timeout_s: wall seconds without telemetry;
    breach_tolerance_m: how far outside the box before an abort (m)."""

    fence_m: float = 150.0
    floor_m: float = 3.0
    ceiling_m: float = 40.0
    tilt_deg: float = 35.0
    saturation_s: float = 0.5
    link_timeout_s: float = 3.0
    breach_tolerance_m: float = 2.0

    def validate(self) -> None:
        """ValueError naming the option."""
        checks = [("fence", self.fence_m, 10.0, 10000.0), ("floor", self.floor_m, 0.5, 1000.0),
                  ("ceiling", self.ceiling_m, 2.0, 1000.0), ("tilt limit", self.tilt_deg, 5.0, 80.0),
                  ("saturation limit", self.saturation_s, 0.05, 10.0),
                  ("link timeout", self.link_timeout_s, 0.5, 60.0)]  # fmt: skip
        for name, v, lo, hi in checks:
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{name} {v!r}: allowed range is [{lo:g}, {hi:g}]")
        if self.floor_m >= self.ceiling_m:
            raise ValueError(f"floor {self.floor_m:g} m must be below the ceiling {self.ceiling_m:g} m")


class Guard:
    """The checks of :class:`GuardLimits` about ``home_ned`` (the autopilot's local frame, m)."""

    def __init__(self, limits: GuardLimits, home_ned: np.ndarray) -> None:
        limits.validate()
        self.limits = limits
        f = limits.fence_m
        self.home = np.asarray(home_ned, dtype=float).copy()
        self.box = Supervisor(SafetyLimits(box_min_ned=(-f, -f, -limits.ceiling_m), box_max_ned=(f, f, 0.0),
                                           min_altitude_m=min(limits.floor_m, limits.ceiling_m / 2),
                                           max_altitude_m=limits.ceiling_m, time_limit_s=1e9,
                                           breach_tolerance_m=limits.breach_tolerance_m,
                                           link_timeout_s=limits.link_timeout_s), self.home)  # fmt: skip
        self._sat_since: float | None = None
        self.max_tilt_deg = 0.0
        self.max_saturated_s = 0.0

    def position(self, pos: np.ndarray, manoeuvring: bool) -> Abort | None:
        """``geofence`` outside the box or above the ceiling; ``floor`` below the floor while manoeuvring."""
        a = self.box.check_vehicle(pos)
        if a is not None:
            return a
        alt = float(self.home[2] - pos[2])
        if manoeuvring and alt < self.limits.floor_m - self.limits.breach_tolerance_m:
            return Abort("floor", f"altitude {alt:.1f} m below the floor of {self.limits.floor_m:g} m during the "
                         "manoeuvre")  # fmt: skip
        return None

    def attitude(self, tilt_rad: float | None) -> Abort | None:
        """``attitude`` when the tilt from level exceeds the limit."""
        if tilt_rad is None:
            return None
        deg = math.degrees(tilt_rad)
        self.max_tilt_deg = max(self.max_tilt_deg, deg)
        if deg > self.limits.tilt_deg:
            return Abort("attitude", f"tilt {deg:.1f} deg beyond the limit of {self.limits.tilt_deg:g} deg")
        return None

    def outputs(self, t: float, u: np.ndarray, tol: float = 0.002) -> Abort | None:
        """``saturation`` when some motor output (normalized, 0..1) has sat at either end of its range for
        longer than the limit; ``t`` is the outputs' time stamp (s)."""
        sat = bool(np.any((u <= tol) | (u >= 1.0 - tol)))
        if not sat:
            self._sat_since = None
            return None
        if self._sat_since is None or t < self._sat_since:
            self._sat_since = t
        run = t - self._sat_since
        self.max_saturated_s = max(self.max_saturated_s, run)
        if run > self.limits.saturation_s:
            which = ", ".join(f"{i + 1} at {'0' if x <= tol else '1'}" for i, x in enumerate(u)
                              if x <= tol or x >= 1 - tol)  # fmt: skip
            return Abort("saturation", f"motor outputs saturated for {run:.2f} s (limit {self.limits.saturation_s:g} s;"
                         f" output {which})")  # fmt: skip
        return None
