"""The mean wind: an air-mass velocity at a reference height, step changes in time, a height profile.

SI units; NED (x north, y east, z down; the ground at z = 0, altitude = -z); wind = air-mass
velocity in NED (a 10 m/s wind *from* the north is ``[-10, 0, 0]``); directions are
meteorological from-directions in degrees (0 = from north, 90 = from east).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vehicle.frames import velocity_from_speed_direction

Vec3 = tuple[float, float, float]

_PROFILES = ("uniform", "log")


def as_vec3(value: Iterable[float], name: str) -> Vec3:
    """Return ``value`` as a tuple of three finite floats, or raise ``ValueError`` naming it."""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be 3 finite numbers (m/s, NED), got {value!r}") from exc
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers (m/s, NED), got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def check_finite(value: float, name: str, allowed: str, ok: bool) -> float:
    """Raise ``ValueError`` naming ``name`` and its ``allowed`` range unless finite and ``ok``."""
    v = float(value)
    if not math.isfinite(v) or not ok:
        raise ValueError(f"{name} must be {allowed}, got {value!r}")
    return v


@dataclass(frozen=True)
class WindChange:
    """A step change of the mean wind: from time ``t_s`` (s) on, the air-mass velocity at the
    reference height is ``velocity_ned`` (m/s, NED)."""

    t_s: float
    velocity_ned: Vec3

    def __post_init__(self) -> None:
        t = check_finite(self.t_s, "WindChange.t_s", "a finite time in s", True)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(
            self, "velocity_ned", as_vec3(self.velocity_ned, "WindChange.velocity_ned")
        )


@dataclass(frozen=True)
class SteadyWind:
    """Mean (non-turbulent) wind.

    Attributes:
        velocity_ned: air-mass velocity at ``reference_height_m`` before the first change
            (m/s, NED).
        changes: step changes; sorted by time on construction, times must be finite and
            strictly increasing. The mean at time t is the last change with ``t_s <= t``,
            else ``velocity_ned``.
        profile: ``"uniform"`` (no height dependence) or ``"log"`` (horizontal components
            scaled by ``ln(max(h, z0)/z0) / ln(z_ref/z0)`` with h = -z the altitude above
            ground; the vertical component is not scaled, and the wind is 0 at/below z0).
        reference_height_m: z_ref, the height at which the velocities are given (m, > 0).
        roughness_length_m: z0 of the log profile (m, 0 < z0 < z_ref).
    """

    velocity_ned: Vec3
    changes: tuple[WindChange, ...] = ()
    profile: str = "uniform"
    reference_height_m: float = 10.0
    roughness_length_m: float = 0.1

    def __post_init__(self) -> None:
        object.__setattr__(self, "velocity_ned", as_vec3(self.velocity_ned, "velocity_ned"))
        changes = []
        for c in self.changes:
            if isinstance(c, WindChange):
                changes.append(c)
            else:
                try:
                    t_s, vel = c
                except (TypeError, ValueError) as exc:
                    raise ValueError(
                        f"changes must hold WindChange or (t_s, velocity_ned) pairs, got {c!r}"
                    ) from exc
                changes.append(WindChange(t_s, vel))
        changes.sort(key=lambda c: c.t_s)
        for a, b in zip(changes, changes[1:], strict=False):
            if not b.t_s > a.t_s:
                raise ValueError(
                    f"changes must have strictly increasing t_s (s), got {a.t_s} twice"
                )
        object.__setattr__(self, "changes", tuple(changes))
        if self.profile not in _PROFILES:
            raise ValueError(f"profile must be one of {_PROFILES}, got {self.profile!r}")
        z_ref = check_finite(
            self.reference_height_m,
            "reference_height_m",
            "a finite height > 0 (m)",
            self.reference_height_m > 0,
        )
        z0 = check_finite(
            self.roughness_length_m,
            "roughness_length_m",
            f"a finite length with 0 < z0 < reference_height_m = {z_ref} (m)",
            0 < self.roughness_length_m < z_ref,
        )
        object.__setattr__(self, "reference_height_m", z_ref)
        object.__setattr__(self, "roughness_length_m", z0)

    velocity_from_speed_direction = staticmethod(velocity_from_speed_direction)

    @classmethod
    def from_speed_direction(
        cls, speed_ms: float, from_deg: float, vertical_ms: float = 0.0, **kwargs: Any
    ) -> SteadyWind:
        """Constant wind of ``speed_ms`` (m/s) from ``from_deg`` (deg); kwargs go to the class."""
        return cls(velocity_from_speed_direction(speed_ms, from_deg, vertical_ms), **kwargs)

    @classmethod
    def direction_steps(
        cls,
        speed_ms: float,
        from_degs: Sequence[float],
        interval_s: float,
        **kwargs: Any,
    ) -> SteadyWind:
        """Constant speed, new from-direction every ``interval_s`` s (anemotaxis scenarios).

        ``from_degs[0]`` holds on [0, interval_s), ``from_degs[k]`` from ``k * interval_s`` on.
        """
        if len(from_degs) == 0:
            raise ValueError("from_degs must hold at least one direction (deg)")
        step = check_finite(interval_s, "interval_s", "a finite time > 0 (s)", interval_s > 0)
        vels = [velocity_from_speed_direction(speed_ms, d) for d in from_degs]
        changes = tuple(WindChange(k * step, v) for k, v in enumerate(vels) if k > 0)
        return cls(vels[0], changes=changes, **kwargs)

    def schedule_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Schedule as kernel arrays: times (K+1,) with a leading -inf, velocities (K+1, 3)."""
        times = np.array([-np.inf] + [c.t_s for c in self.changes], dtype=np.float64)
        vels = np.array(
            [self.velocity_ned] + [c.velocity_ned for c in self.changes], dtype=np.float64
        )
        return times, np.ascontiguousarray(vels)
