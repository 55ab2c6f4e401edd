"""The wind-model interface of the world, and the registry a scenario names its model from.

A wind model is anything with ``mean(t, pos_ned)`` and ``velocity(t, pos_ned)`` (air-mass
velocity, m/s NED, at NED points in m, time in s): the vehicle, the plume and the truth the
estimator is scored against all sample the same object. A model may also offer a numba fast
path (:meth:`WindModel.kernel` returning a :class:`~sitl.world.wind.kernel.WindKernel`); the
world's fused physics loop then samples it without leaving compiled code. A model without one
(``kernel()`` returns None) is sampled in Python once per physics tick: correct, slower.

A scenario picks its model with ``[wind] model = "NAME"`` (default ``"steady"``, the built-in
:class:`~sitl.world.wind.field.WindField`). Register a new one with :func:`register_wind_model`;
``sitl/templates/wind_model.py`` is a complete example.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

from sitl.world.wind.field import WindField
from sitl.world.wind.kernel import WindKernel
from sitl.world.wind.steady import SteadyWind
from sitl.world.wind.turbulence import KaimalTurbulence


@runtime_checkable
class WindModel(Protocol):
    """What the world needs of a wind field (SI, NED, wind = air-mass velocity)."""

    @property
    def reference_height_m(self) -> float:
        """Height (m above ground) at which the model's nominal wind holds (SIM_WIND_* reads it there)."""
        ...

    def mean(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Mean (non-turbulent) air-mass velocity (3,) m/s at NED point (3,) m, time t s."""
        ...

    def velocity(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Air-mass velocity (mean + turbulence) m/s at NED point(s) (3,) or (N, 3) m, time t s."""
        ...

    def kernel(self) -> WindKernel | None:
        """The numba fast path, or None (sampled through :meth:`velocity` each physics tick)."""
        ...


#: A factory builds a model from the scenario's mean wind, its turbulence (or None), the
#: model's own options (the ``[wind]`` keys the built-in parser does not know, as a dict) and a seed.
WindFactory = Callable[[SteadyWind, KaimalTurbulence | None, dict[str, Any], np.random.SeedSequence], WindModel]


def _steady(steady: SteadyWind, turbulence: KaimalTurbulence | None, options: dict[str, Any],
            seed: np.random.SeedSequence) -> WindModel:  # fmt: skip
    if options:
        raise ValueError(f"wind model 'steady' takes no extra options, got {', '.join(sorted(options))}")
    return WindField(steady, turbulence, seed)


WIND_MODELS: dict[str, WindFactory] = {"steady": _steady}


def register_wind_model(name: str, factory: WindFactory) -> None:
    """Make ``[wind] model = name`` build ``factory(steady, turbulence, options, seed)``."""
    if not name or not name.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"wind model name {name!r}: use letters, digits, '-' and '_'")
    WIND_MODELS[name] = factory


def make_wind(model: str, steady: SteadyWind, turbulence: KaimalTurbulence | None, options: dict[str, Any],
              seed: np.random.SeedSequence) -> WindModel:  # fmt: skip
    """Build the named model; KeyError-free: an unknown name is a ValueError listing the known ones."""
    if model not in WIND_MODELS:
        raise ValueError(f"wind model {model!r}: known models are {', '.join(sorted(WIND_MODELS))}")
    return WIND_MODELS[model](steady, turbulence, options, seed)
