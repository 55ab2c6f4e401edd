"""The solved urban mean wind field, its numba samplers and the turbulence multiplier hook.

Array layout of :class:`UrbanWindField` (grid of :class:`~.config.GridSpec`, nx x ny x nz cells,
k counts upward from the ground, cell (i, j, k) centred at north x0 + (i + 0.5) dx, east
y0 + (j + 0.5) dy, height (k + 0.5) dz):

    u_n  (nx + 1, ny, nz)  north air velocity (m/s) on the x-faces (north x0 + i dx)
    v_e  (nx, ny + 1, nz)  east air velocity (m/s) on the y-faces (east y0 + j dy)
    w_d  (nx, ny, nz + 1)  DOWN air velocity (m/s, NED) on the z-faces (height k dz; k = 0 ground)
    cell_building (nx, ny, nz) int32   building index of each cell, -1 for air
    zone          (nx, ny, nz) int8    parameterization zone (``ZONE_*`` of :mod:`.parameterizations`)
    turbulence_multiplier (nx, ny, nz) see below

Sampling (:func:`urban_wind_at`, the single implementation): each component is interpolated on
its own staggered grid, bilinear horizontally; vertically the horizontal components are
interpolated as a ratio to the upstream log law (so the upstream profile is reproduced exactly
between levels and continues as a log law below the first cell centre), w linearly. Zero inside
a building (exact prism geometry); the upstream log profile outside the grid (sides, top).

Turbulence hook. The project's Kaimal field has one sigma_u at all heights (right for a neutral
surface layer, where sigma_u ~ 2.4 u* does not change with height). Among buildings it should
follow the local mean wind and be stronger in separated flow, so the multiplier per cell is::

    m = max(|V_mean| / U_up(h), enhancement * U_zone / U_ref)      (0 inside buildings)

with U_up(h) the upstream log-law speed at the cell's height (floored at 0.05 U_ref), U_zone
the roof-height speed U_H of the building whose cavity, street canyon or rooftop vortex holds
the cell (tapered linearly to 0 across its far wake) and ``enhancement`` =
``UrbanOptions.wake_turbulence_enhancement`` (1.5: wind-tunnel cube wakes show sigma_u / U_H of
0.2-0.3, about 1.5 x an upstream intensity of 0.15-0.2). m = 1 in the undisturbed flow, so far
from buildings the turbulence is exactly today's; it drops in sheltered, slow air, rises where
streets and roofs speed the wind up, and is at least 1.5 U_H / U_ref in recirculation. The lead
scales the Kaimal perturbation sampled at a point by ``m`` there
(:func:`urban_turbulence_multiplier_at`; 1 outside the grid).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import UrbanScene
from .geometry import BuildingArrays, inside_many, reflect_many
from .initial_field import profile_array
from .sampling import (
    urban_turbulence_multiplier_at,
    urban_wind_mean,
    urban_wind_mean_many,
)
from .solver import SolveStats, divergence


def turbulence_multiplier(
    u_n: np.ndarray, v_e: np.ndarray, w_d: np.ndarray, solid: np.ndarray, u_zone: np.ndarray,
    scene: UrbanScene,
) -> np.ndarray:
    """Per-cell ``max(|V| / U_up(h), enhancement U_zone / U_ref)`` (module docstring), 0 in buildings."""
    wind = scene.wind
    if wind.speed_m_s <= 0.0:
        return np.where(solid, 0.0, 1.0)
    sn = 0.5 * (u_n[1:] + u_n[:-1])
    se = 0.5 * (v_e[:, 1:] + v_e[:, :-1])
    sd = 0.5 * (w_d[:, :, 1:] + w_d[:, :, :-1])
    speed = np.sqrt(sn * sn + se * se + sd * sd)
    heights = (np.arange(solid.shape[2]) + 0.5) * scene.grid.dz
    upstream = np.maximum(wind.speed_at(heights), 0.05 * wind.speed_m_s)
    m = np.maximum(speed / upstream, scene.options.wake_turbulence_enhancement * u_zone / wind.speed_m_s)
    m[solid] = 0.0
    return m


@dataclass(eq=False)
class UrbanWindField:
    """A solved mean wind field (layout in the module docstring) with its samplers.

    Build with :func:`~.solve.solve_urban_wind` or load with :func:`~.cache.load_or_solve`.
    """

    scene: UrbanScene
    u_n: np.ndarray
    v_e: np.ndarray
    w_d: np.ndarray
    cell_building: np.ndarray
    zone: np.ndarray
    turbulence_multiplier: np.ndarray
    stats: SolveStats | None = None
    geometry: BuildingArrays = field(init=False, repr=False)
    _args: tuple = field(init=False, repr=False, default=())

    def __post_init__(self) -> None:
        g = self.scene.grid
        nx, ny, nz = g.shape
        shapes = {"u_n": (nx + 1, ny, nz), "v_e": (nx, ny + 1, nz), "w_d": (nx, ny, nz + 1),
                  "cell_building": (nx, ny, nz), "zone": (nx, ny, nz), "turbulence_multiplier": (nx, ny, nz)}
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"{name} has shape {getattr(self, name).shape}, the grid needs {shape}")
        self.geometry = BuildingArrays.from_buildings(self.scene.buildings)
        gp = np.array([g.x_min_m, g.y_min_m, g.spacing_m, g.spacing_m, g.dz])
        wp = np.concatenate([profile_array(self.scene), np.array(self.scene.wind.direction_ned)])
        self._args = (gp, self.u_n, self.v_e, self.w_d, wp, *self.geometry.args())

    def kernel_args(self) -> tuple:
        """Arguments after the position of :func:`urban_wind_mean` / :func:`urban_wind_mean_many`:
        (gp, u_n, v_e, w_d, wp, verts, offsets, heights, bbox)."""
        return self._args

    def mean(self, pos_ned: np.ndarray) -> np.ndarray:
        """Mean air-mass velocity, m/s NED, at NED point(s) (3,) -> (3,) or (N, 3) -> (N, 3)."""
        pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
        if pos.shape == (3,):
            return urban_wind_mean(pos, *self._args)
        if pos.ndim == 2 and pos.shape[1] == 3:
            return urban_wind_mean_many(pos, *self._args)
        raise ValueError(f"pos_ned must have shape (3,) or (N, 3) (m, NED), got {pos.shape}")

    def inside(self, points_ned: np.ndarray) -> np.ndarray:
        """bool (N,): NED points (N, 3) inside a building (exact geometry)."""
        pts = np.ascontiguousarray(np.atleast_2d(points_ned), dtype=np.float64)
        return inside_many(pts, *self.geometry.args())

    def reflect(self, points_ned: np.ndarray, prev_ned: np.ndarray) -> tuple[np.ndarray, int]:
        """(points, n moved): points that entered a building since ``prev_ned`` mirrored out."""
        pts = np.ascontiguousarray(points_ned, dtype=np.float64)
        prev = np.ascontiguousarray(prev_ned, dtype=np.float64)
        if pts.shape != prev.shape or pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points and prev must both be (N, 3) NED m, got {pts.shape} and {prev.shape}")
        return reflect_many(pts, prev, *self.geometry.args())

    def turbulence_multiplier_at(self, points_ned: np.ndarray) -> np.ndarray:
        """Turbulence multiplier (N,) at NED points (N, 3) (module docstring)."""
        pts = np.ascontiguousarray(np.atleast_2d(points_ned), dtype=np.float64)
        gp, _, _, _, wp, *geo = self._args
        return urban_turbulence_multiplier_at(pts, gp, self.turbulence_multiplier, wp, *geo)

    def divergence(self) -> np.ndarray:
        """Discrete divergence (1/s) at the cell centres (nx, ny, nz); meaningful in air cells."""
        g = self.scene.grid
        return divergence(self.u_n, self.v_e, -self.w_d, g.spacing_m, g.spacing_m, g.dz)

    def max_divergence_ratio(self) -> float:
        """max |div| over air cells, in units of U_ref / dx (the mass-consistency figure)."""
        u_ref = max(self.scene.wind.speed_m_s, 1e-12)
        div = np.abs(self.divergence())[self.cell_building < 0]
        return float(div.max() * self.scene.grid.spacing_m / u_ref) if div.size else 0.0

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(north (nx,), east (ny,), height above ground (nz,)) of the cell centres, m."""
        g = self.scene.grid
        nx, ny, nz = g.shape
        return (
            g.x_min_m + (np.arange(nx) + 0.5) * g.spacing_m,
            g.y_min_m + (np.arange(ny) + 0.5) * g.spacing_m,
            (np.arange(nz) + 0.5) * g.dz,
        )

