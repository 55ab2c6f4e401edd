"""Template: a wind model for the world (copy, rename, fill in).

A wind model answers ``mean(t, pos_ned)`` and ``velocity(t, pos_ned)`` (air-mass velocity, m/s NED,
at NED points in m, time in s); the vehicle, the plume and the estimator's truth all sample it.
``kernel()`` returns None here: the world then samples :meth:`velocity` in Python once per physics
tick (correct, slower). A built-in model offers a numba fast path instead (a
:class:`~sitl.world.wind.kernel.WindKernel`).

This one is a sea-breeze-like wind: the scenario's mean wind, turning slowly with time.
Register it and select it in a scenario::

    from sitl.world.wind import register_wind_model
    register_wind_model("turning", make_turning_wind)

    [wind]
    model = "turning"
    speed_m_s = 5.0
    from_deg = 0.0
    [wind.options]
    turn_deg_per_min = 10.0
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sitl.world.wind import KaimalTurbulence, SteadyWind, WindKernel


class TurningWind:
    """The steady wind's initial velocity rotated by ``turn_rad_s * t`` about the vertical."""

    def __init__(self, steady: SteadyWind, turn_rad_s: float) -> None:
        self.base = np.asarray(steady.velocity_ned, dtype=float)
        self.turn = float(turn_rad_s)
        self.reference_height_m = steady.reference_height_m

    def mean(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        a = self.turn * t
        c, s = math.cos(a), math.sin(a)
        n, e, d = self.base
        return np.array([c * n - s * e, s * n + c * e, d])

    def velocity(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        p = np.asarray(pos_ned, dtype=float)
        w = self.mean(t, p[0] if p.ndim == 2 else p)
        return np.tile(w, (len(p), 1)) if p.ndim == 2 else w

    def kernel(self) -> WindKernel | None:
        return None


def make_turning_wind(steady: SteadyWind, turbulence: KaimalTurbulence | None, options: dict[str, Any],
                      seed: np.random.SeedSequence) -> TurningWind:  # fmt: skip
    """The factory a scenario's ``[wind] model = "turning"`` calls (``[wind.options]`` in ``options``)."""
    unknown = set(options) - {"turn_deg_per_min"}
    if unknown:
        raise ValueError(f"wind.options: unknown key(s) {', '.join(sorted(unknown))}; allowed: turn_deg_per_min")
    if turbulence is not None:
        raise ValueError("the turning wind has no turbulence: set [turbulence] model = 'none'")
    return TurningWind(steady, math.radians(float(options.get("turn_deg_per_min", 10.0))) / 60.0)
