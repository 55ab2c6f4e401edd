"""The mean wind a search vehicle is in among known buildings, for the urban STE likelihood.

The mission knows the buildings (:class:`mission.obstacles.Obstacles`: footprints and roof
heights) and estimates the wind where it flies. From both it computes windseek's urban
diagnostic wind field (:mod:`urbanflow`: QUIC-URB-style Roeckle parameterizations and a
mass-consistent adjustment) with the *estimated* wind as the upstream inflow -- never the
simulator's truth -- and keeps one horizontal slice of it at the flight altitude: an
:class:`UrbanPlane`, the input of the backward-trajectory kernels of
:mod:`mission.strategies.ste_urban`.

Inflow: the estimated horizontal air-mass velocity ``wind_ne`` [m/s NED] measured at
``inflow_height_m`` -- above the roofs, where the buildings hardly turn it (``ste_city``: the
vehicle climbs there first; the wind down in a lee can blow the other way) -- is taken as the
upstream log profile at that height (roughness ``ROUGHNESS_M``), so the profile's reference speed
at ``REFERENCE_HEIGHT_M`` is ``|wind| ln(10 / z0) / ln(h / z0)``. Grid: the
buildings' bounding box plus ``margin_m`` on every side, ``cell_m`` cells (horizontal and
vertical), three times the tallest roof high. The solve takes about 1 s on one core for the
paper's six blocks (4 m cells): it is done once, when the first usable wind arrives (a wind that
turns later is not followed: see ``mission/README.md``).

Plain synchronous deterministic code without I/O. Units SI; frame local NED (north, east) of
the mission (the obstacles' frame); wind = air-mass velocity in NED; altitudes above home (the
ground at home).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mission.obstacles import Building
from urbanflow.config import ConfigError, GridSpec, LogWindProfile, PolygonBuilding, UrbanScene
from urbanflow.solve import solve_urban_wind

#: Roughness length of the inflow profile [m] (the scenarios' default).
ROUGHNESS_M = 0.1
#: Reference height of the inflow profile [m].
REFERENCE_HEIGHT_M = 10.0
#: Column layout of :attr:`UrbanPlane.gp` (one float64 array for the kernels).
GP_N0, GP_E0, GP_CELL, GP_NX, GP_NY, GP_UPN, GP_UPE, GP_SPEED = range(8)


class UrbanModelError(ValueError):
    """The urban wind model cannot be built or used here (the message says why)."""


@dataclass(frozen=True, eq=False)
class UrbanPlane:
    """A horizontal slice of the urban mean wind at the flight altitude.

    ``gp``: (north0, east0, cell [m], nx, ny, upwind north, upwind east (unit vector toward where
    the inflow comes from), inflow speed at the flight altitude [m/s]); ``un``, ``ue`` (nx, ny):
    north / east air-mass velocity [m/s] at the cell corners north0 + i cell, east0 + j cell;
    ``solid`` (nx, ny) uint8: 1 where the corner lies inside a building at the flight altitude.
    ``wind_ne``: the inflow it was solved for, at the flight altitude [m/s NED]."""

    gp: np.ndarray
    un: np.ndarray
    ue: np.ndarray
    solid: np.ndarray
    wind_ne: tuple[float, float]

    def args(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(gp, un, ue, solid): the arguments of the kernels."""
        return self.gp, self.un, self.ue, self.solid

    def solid_at(self, north: float, east: float) -> bool:
        """Whether (north, east) [m] lies inside a building at the flight altitude (nearest corner)."""
        g = self.gp
        i = int(round((north - g[GP_N0]) / g[GP_CELL]))
        j = int(round((east - g[GP_E0]) / g[GP_CELL]))
        if 0 <= i < self.solid.shape[0] and 0 <= j < self.solid.shape[1]:
            return bool(self.solid[i, j])
        return False


def _scene(buildings: Sequence[Building], wind_ne: np.ndarray, inflow_height_m: float, cell_m: float,
           margin_m: float) -> UrbanScene:
    """The urban scene of the known buildings with the estimated wind as its inflow."""
    speed = float(np.hypot(wind_ne[0], wind_ne[1]))
    if not (math.isfinite(speed) and speed > 0.05):
        raise UrbanModelError(f"estimated wind {wind_ne.tolist()} m/s: no usable inflow direction")
    if not (math.isfinite(inflow_height_m) and inflow_height_m > 2.0 * ROUGHNESS_M):
        raise UrbanModelError(f"inflow height {inflow_height_m} m: too low for the inflow profile")
    ref = speed * math.log(REFERENCE_HEIGHT_M / ROUGHNESS_M) / math.log(inflow_height_m / ROUGHNESS_M)
    from_deg = math.degrees(math.atan2(-wind_ne[1], -wind_ne[0]))
    polys = tuple(PolygonBuilding(tuple((float(a), float(b)) for a, b in bd.footprint), float(bd.height_m), bd.name)
                  for bd in buildings)
    pts = np.concatenate([bd.footprint for bd in buildings])
    lo = np.floor((pts.min(axis=0) - margin_m) / cell_m) * cell_m
    hi = np.ceil((pts.max(axis=0) + margin_m) / cell_m) * cell_m
    top = math.ceil(max(3.0 * max(bd.height_m for bd in buildings), 8.0 * cell_m) / cell_m) * cell_m
    grid = GridSpec(float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1]), float(top), cell_m)
    return UrbanScene(polys, LogWindProfile(ref, from_deg, REFERENCE_HEIGHT_M, ROUGHNESS_M), grid, name="mission")


def build_plane(buildings: Sequence[Building], wind_ne: np.ndarray, altitude_m: float,
                inflow_height_m: float | None = None, cell_m: float = 4.0, margin_m: float = 60.0,
                plane_cell_m: float = 2.0) -> UrbanPlane:
    """Solve the urban field of ``buildings`` for the inflow ``wind_ne`` [m/s NED, horizontal,
    measured ``inflow_height_m`` m above ground, default ``altitude_m``] and slice it at the flight
    altitude ``altitude_m`` [m] on ``plane_cell_m`` corners. Raises :class:`UrbanModelError` (no
    buildings, no usable wind, a bad geometry)."""
    if not buildings:
        raise UrbanModelError("no buildings known to the mission: the urban model has nothing to add")
    w = np.asarray(wind_ne, dtype=float)[:2]
    try:
        scene = _scene(buildings, w, altitude_m if inflow_height_m is None else inflow_height_m, cell_m, margin_m)
        field = solve_urban_wind(scene)
    except ConfigError as e:
        raise UrbanModelError(f"the known buildings do not make an urban wind scene: {e}") from None
    g = scene.grid
    nx = int(round(g.length_x_m / plane_cell_m)) + 1
    ny = int(round(g.length_y_m / plane_cell_m)) + 1
    nn = g.x_min_m + plane_cell_m * np.arange(nx)
    ee = g.y_min_m + plane_cell_m * np.arange(ny)
    pts = np.stack([np.repeat(nn, ny), np.tile(ee, nx), np.full(nx * ny, -float(altitude_m))], axis=1)
    v = field.mean(pts)
    solid = field.inside(pts).astype(np.uint8).reshape(nx, ny)
    speed = float(scene.wind.speed_at(altitude_m))
    up = -w / float(np.hypot(w[0], w[1]))
    gp = np.array([g.x_min_m, g.y_min_m, plane_cell_m, nx, ny, up[0], up[1], speed])
    un = np.ascontiguousarray(v[:, 0].reshape(nx, ny))
    ue = np.ascontiguousarray(v[:, 1].reshape(nx, ny))
    un[solid > 0] = 0.0
    ue[solid > 0] = 0.0
    return UrbanPlane(gp, un, ue, solid, (float(-up[0] * speed), float(-up[1] * speed)))


def uniform_plane(wind_ne: tuple[float, float], extent: tuple[float, float, float, float],
                  cell_m: float = 2.0) -> UrbanPlane:
    """A slice of a uniform wind ``wind_ne`` [m/s NED] without buildings over ``extent`` = (north
    min, north max, east min, east max) [m]: the open field (kernel warm-up, tests)."""
    n0, n1, e0, e1 = extent
    nx, ny = int(round((n1 - n0) / cell_m)) + 1, int(round((e1 - e0) / cell_m)) + 1
    speed = math.hypot(*wind_ne)
    gp = np.array([n0, e0, cell_m, nx, ny, -wind_ne[0] / speed, -wind_ne[1] / speed, speed])
    return UrbanPlane(gp, np.full((nx, ny), wind_ne[0]), np.full((nx, ny), wind_ne[1]),
                      np.zeros((nx, ny), dtype=np.uint8), (float(wind_ne[0]), float(wind_ne[1])))
