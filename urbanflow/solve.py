"""Solve an urban scene: voxels, initial field, mass-consistent adjustment, zones, turbulence hook.

Plain synchronous code without I/O; the cached entry point is :func:`~.cache.load_or_solve`.
"""

from __future__ import annotations

import time
from dataclasses import replace

from .config import UrbanScene
from .field import UrbanWindField, turbulence_multiplier
from .geometry import BuildingArrays, voxelize
from .initial_field import building_params, initial_field, options_array, profile_array, zone_map
from .solver import mass_consistent


def solve_urban_wind(scene: UrbanScene) -> UrbanWindField:
    """The QUIC-URB-style mean wind field of ``scene`` (seconds to tens of seconds; cache it)."""
    g = scene.grid
    nx, ny, nz = g.shape
    dx, dz = g.spacing_m, g.dz
    geom = BuildingArrays.from_buildings(scene.buildings)
    cell_building = voxelize(g.x_min_m, g.y_min_m, dx, dx, dz, nx, ny, nz, *geom.args())
    solid = cell_building >= 0
    t0 = time.process_time()
    u0, v0, w0 = initial_field(scene, geom)
    t_init = time.process_time() - t0
    u, v, w_up, stats = mass_consistent(
        u0, v0, w0, solid, dx, dx, dz, alpha_ratio=scene.options.alpha_ratio,
        tol=scene.options.solver_tol, amg=scene.options.amg,
    )
    en, ee = scene.wind.direction_ned
    zone, u_zone = zone_map(
        g.x_min_m, g.y_min_m, dx, dx, dz, cell_building, en, ee, profile_array(scene),
        *geom.args()[:3], building_params(scene), options_array(scene),
    )
    w_d = -w_up
    tm = turbulence_multiplier(u, v, w_d, solid, u_zone, scene)
    return UrbanWindField(scene, u, v, w_d, cell_building, zone, tm, replace(stats, initial_s=t_init))
