"""The urban wind as the world's wind model: the solved mean field plus Kaimal turbulence scaled by
the field's multiplier (stronger in wakes and canyons, weaker in sheltered air, none in buildings).

The turbulence series is the open field's (:class:`~sitl.world.wind.field.WindField`: synthesized
for the upstream reference speed, advected with it, Taylor-frozen); the numba fast path is the
built-in wind kernel with its urban branch on (:class:`~sitl.world.wind.kernel.WindKernel`), so the
vehicle, the plume and the estimator's truth all sample the one field. Units SI, NED, wind =
air-mass velocity.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sitl.world.urban.cache import load_or_solve
from sitl.world.wind.field import WindField
from sitl.world.wind.kernel import WindKernel, wind_mean, wind_velocity, wind_velocity_many
from sitl.world.wind.steady import SteadyWind
from sitl.world.wind.turbulence import KaimalTurbulence
from urbanflow.config import UrbanScene
from urbanflow.field import UrbanWindField


class UrbanWind:
    """A :class:`~sitl.world.wind.model.WindModel` over a solved :class:`UrbanWindField`."""

    def __init__(self, field: UrbanWindField, steady: SteadyWind, turbulence: KaimalTurbulence | None,
                 seed: int | np.random.SeedSequence) -> None:  # fmt: skip
        self.field = field
        self.open_field = WindField(steady, turbulence, seed)  # the turbulence series (and its seed stream)
        k = self.open_field.kernel()
        gp, u_n, v_e, w_d, wp, verts, offsets, heights, bbox = field.kernel_args()
        self._kernel = k._replace(urban_on=True, ugp=gp, u_n=u_n, v_e=v_e, w_d=w_d, uwp=wp,
                                  tm=np.ascontiguousarray(field.turbulence_multiplier, dtype=np.float64),
                                  verts=verts, offsets=offsets, heights=heights, bbox=bbox)  # fmt: skip

    @property
    def reference_height_m(self) -> float:
        return self.field.scene.wind.reference_height_m

    @property
    def turbulence(self) -> KaimalTurbulence | None:
        """The Kaimal turbulence (the plume takes its frozen variance out of its meander budget)."""
        return self.open_field.turbulence

    @property
    def turbulence_mean_speed_ms(self) -> float:
        return self.open_field.turbulence_mean_speed_ms

    def kernel(self) -> WindKernel:
        return self._kernel

    def mean(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
        if pos.shape != (3,):
            raise ValueError(f"pos_ned must have shape (3,) (m, NED), got {pos.shape}")
        return wind_mean(float(t), pos, self._kernel)

    def velocity(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
        if pos.shape == (3,):
            return wind_velocity(float(t), pos, self._kernel)
        if pos.ndim == 2 and pos.shape[1] == 3:
            return wind_velocity_many(float(t), pos, self._kernel)
        raise ValueError(f"pos_ned must have shape (3,) or (N, 3) (m, NED), got {pos.shape}")


def make_urban_wind(steady: SteadyWind, turbulence: KaimalTurbulence | None, options: dict[str, Any],
                    seed: np.random.SeedSequence) -> UrbanWind:  # fmt: skip
    """The ``urban`` wind model: ``options["scene"]`` is the scenario's :class:`UrbanScene` (its wind
    profile is the scenario's ``[wind]``); the solved field is cached (``options["cache_dir"]``,
    default ``~/.cache/windseek/urban/``), so only the first run of a city solves it."""
    scene = options.get("scene")
    if not isinstance(scene, UrbanScene):
        raise ValueError("wind model 'urban' needs the scenario's [urban] table (buildings and grid)")
    cache = options.get("cache_dir")
    field = load_or_solve(scene, Path(cache) if cache else None)
    return UrbanWind(field, steady, turbulence, seed)
