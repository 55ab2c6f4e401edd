"""Urban mean wind among buildings: a diagnostic, mass-consistent field of the QUIC-URB kind.

The pure field computation (configuration, geometry, parameterizations, solver, field, samplers)
lives in the top-level package :mod:`urbanflow`, below both the world and the mission (a mission
computes the same field from the buildings it knows and its estimated wind); this package keeps
the world's side: the on-disk cache, the scenario layouts and parser, the world's wind model, and
re-exports the names below.

The paper's Scenario 4 used QUIC (Quick Urban and Industrial Complex) winds. This package builds
the same kind of field from scratch: buildings as extruded footprints (:mod:`.config`), an
upstream log profile, the empirical building parameterizations of Roeckle (1990) and QUIC-URB
(:mod:`.parameterizations`: frontal vortex, rooftop vortex, lee cavity and far wake, street
canyon vortex), then the variational mass-consistent adjustment on a staggered grid, solved with
pyamg multigrid-preconditioned conjugate gradients (:mod:`.solver`). :mod:`.field` holds the
result, :mod:`.sampling` samples it with numba (and the turbulence multiplier hook),
:mod:`.geometry` answers "inside a building?" and reflects puffs off walls, :mod:`.cache`
stores solved fields by a hash of the scene. Nothing is computed at import.

Conventions: SI units, NED (x north, y east, z down, ground z = 0; configuration heights are
positive metres above ground), wind = air-mass velocity in NED, directions in configuration are
meteorological from-directions in degrees.

Typical use::

    from sitl.world.urban import load_or_solve, paper_s4_scene
    field = load_or_solve(paper_s4_scene())          # ~20 s the first time, then from the cache
    field.mean(np.array([340.0, 30.0, -5.0]))        # m/s NED
    urban_wind_mean(pos, *field.kernel_args())       # the same from numba code
"""

from __future__ import annotations

import importlib
from typing import Any

# Names load on first use (PEP 562): the world's wind kernel imports .sampling on every simulator
# start, and must not pull in the solver (pyamg, scipy.sparse) with the package.
_BY_MODULE = {
    "sitl.world.urban.cache": ("cache_key", "default_cache_dir", "load_field", "load_or_solve", "save_field"),
    "urbanflow.config": ("BoxBuilding", "ConfigError", "GridSpec", "LogWindProfile", "PolygonBuilding",
                         "UrbanOptions", "UrbanScene"),
    "urbanflow.field": ("UrbanWindField",),
    "urbanflow.sampling": ("urban_turbulence_multiplier_at", "urban_wind_at", "urban_wind_mean",
                           "urban_wind_mean_many"),
    "urbanflow.geometry": ("BuildingArrays", "building_at", "inside_many", "reflect_many", "reflect_point"),
    "sitl.world.urban.layouts": ("PAPER_S4_START_NED", "PAPER_S4_SUGGESTED_SOURCE_NED", "cube_array_scene",
                                 "isolated_cube_scene", "paper_s4_scene", "street_canyon_scene"),
    "sitl.world.urban.parse": ("parse_urban_scene",),
    "urbanflow.solve": ("solve_urban_wind",),
}
_EXPORTS = {name: module for module, names in _BY_MODULE.items() for name in names}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'sitl.world.urban' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name]), name)
