"""Urban mean wind among buildings: a diagnostic, mass-consistent field of the QUIC-URB kind.

The paper's Scenario 4 used QUIC (Quick Urban and Industrial Complex) winds. This package builds
the same kind of field from scratch: buildings as extruded footprints (:mod:`.config`), an
upstream log profile, the empirical building parameterizations of Roeckle (1990) and QUIC-URB
(:mod:`.parameterizations`: frontal vortex, rooftop vortex, lee cavity and far wake, street
canyon vortex), then the variational mass-consistent adjustment on a staggered grid, solved with
pyamg multigrid-preconditioned conjugate gradients (:mod:`.solver`). :mod:`.field` samples the
result with numba (and gives the turbulence multiplier hook), :mod:`.geometry` answers "inside a
building?" and reflects puffs off walls, :mod:`.cache` stores solved fields by a hash of the
scene. Nothing is computed at import.

Conventions: SI units, NED (x north, y east, z down, ground z = 0; configuration heights are
positive metres above ground), wind = air-mass velocity in NED, directions in configuration are
meteorological from-directions in degrees.

Typical use::

    from sitl.world.urban import load_or_solve, paper_s4_scene
    field = load_or_solve(paper_s4_scene())          # ~20 s the first time, then from the cache
    field.mean(np.array([340.0, 30.0, -5.0]))        # m/s NED
    urban_wind_mean(pos, *field.kernel_args())       # the same from numba code
"""

from .cache import cache_key, default_cache_dir, load_field, load_or_solve, save_field
from .config import (
    BoxBuilding,
    ConfigError,
    GridSpec,
    LogWindProfile,
    PolygonBuilding,
    UrbanOptions,
    UrbanScene,
)
from .field import UrbanWindField, urban_turbulence_multiplier_at, urban_wind_at, urban_wind_mean, urban_wind_mean_many
from .geometry import BuildingArrays, building_at, inside_many, reflect_many, reflect_point
from .layouts import (
    PAPER_S4_START_NED,
    PAPER_S4_SUGGESTED_SOURCE_NED,
    cube_array_scene,
    isolated_cube_scene,
    paper_s4_scene,
    street_canyon_scene,
)
from .parse import parse_urban_scene
from .solve import solve_urban_wind

__all__ = [
    "PAPER_S4_START_NED",
    "PAPER_S4_SUGGESTED_SOURCE_NED",
    "BoxBuilding",
    "BuildingArrays",
    "ConfigError",
    "GridSpec",
    "LogWindProfile",
    "PolygonBuilding",
    "UrbanOptions",
    "UrbanScene",
    "UrbanWindField",
    "building_at",
    "cache_key",
    "cube_array_scene",
    "default_cache_dir",
    "inside_many",
    "isolated_cube_scene",
    "load_field",
    "load_or_solve",
    "paper_s4_scene",
    "parse_urban_scene",
    "reflect_many",
    "reflect_point",
    "save_field",
    "solve_urban_wind",
    "street_canyon_scene",
    "urban_turbulence_multiplier_at",
    "urban_wind_at",
    "urban_wind_mean",
    "urban_wind_mean_many",
]
