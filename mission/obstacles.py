"""Buildings as exclusion zones of a mission: no setpoint may lead the vehicle into one.

:class:`Obstacles` holds building footprints (polygons in the local NED frame, north/east metres)
with their roof heights (m above home). The safety supervisor (:mod:`mission.safety`) uses it to
clamp every setpoint: a target whose straight path from the vehicle would enter a building (below
its roof plus a margin) is moved back along that path to stay ``margin_m`` clear; the MAVSDK runner
also uploads the footprints to the autopilot as geofence exclusion polygons (as a user would with
PX4), so the autopilot's own fence backs the supervisor up.

Built from a scenario's ``[urban]`` buildings (:meth:`Obstacles.from_buildings`; the runners read the
file, :class:`mission.runners.fence.SiteBuildings`) with shapely (2-D geometry); the module needs no
simulator, so a strategy may plan with it. Units SI, NED; altitudes above home.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from shapely import LineString, Point, Polygon, prepare


@dataclass(frozen=True, eq=False)
class Building:
    """One building: footprint (V, 2) north/east m (local NED), roof height above home (m)."""

    footprint: np.ndarray
    height_m: float
    name: str = ""


class Obstacles:
    """Buildings the vehicle must keep ``margin_m`` away from (see the module docstring)."""

    def __init__(self, buildings: Sequence[Building], margin_m: float = 3.0) -> None:
        if not (math.isfinite(margin_m) and margin_m >= 0.0):
            raise ValueError(f"obstacle margin {margin_m!r}: must be a finite number >= 0 (m)")
        self.buildings = list(buildings)
        self.margin_m = float(margin_m)
        self._shapes = [Polygon(b.footprint) for b in self.buildings]
        self._grown = [s.buffer(self.margin_m) for s in self._shapes]
        for g in self._grown:
            prepare(g)
        self.clamped = 0

    def __len__(self) -> int:
        return len(self.buildings)

    @classmethod
    def from_buildings(cls, buildings: Sequence[Any], margin_m: float = 3.0) -> Obstacles:
        """From the world's building configs (:mod:`urbanflow.config`: ``footprint()``, ``height_m``)."""
        return cls([Building(np.asarray(b.footprint(), dtype=float), float(b.height_m), getattr(b, "name", ""))
                    for b in buildings], margin_m)  # fmt: skip

    def shifted(self, north_m: float, east_m: float) -> Obstacles:
        """The same buildings moved by (north, east) m: from the scenario's frame to an autopilot's
        local frame whose origin lies elsewhere (PX4 puts its origin where its estimator started)."""
        d = np.array([north_m, east_m], dtype=float)
        return Obstacles([Building(b.footprint + d, b.height_m, b.name) for b in self.buildings], self.margin_m)

    def _blocking(self, altitude_m: float) -> list[int]:
        """Buildings a vehicle at ``altitude_m`` above home could hit (roof + margin above it)."""
        return [i for i, b in enumerate(self.buildings) if altitude_m < b.height_m + self.margin_m]

    def inside(self, pos_ned: np.ndarray, home_down_m: float = 0.0) -> int:
        """Index of the building (grown by the margin) the point is in, at its altitude, or -1."""
        alt = home_down_m - float(pos_ned[2])
        p = Point(float(pos_ned[0]), float(pos_ned[1]))
        for i in self._blocking(alt):
            if self._grown[i].contains(p):
                return i
        return -1

    def clamp(self, start_ned: np.ndarray, target_ned: np.ndarray, home_down_m: float = 0.0) -> np.ndarray:
        """``target_ned`` moved back along the straight path from ``start_ned`` so that the path stays
        out of every building grown by the margin (at the lower of the two altitudes). A start
        already inside a grown building: the target is kept only if it leads out of it."""
        start, target = np.asarray(start_ned, float), np.asarray(target_ned, float)
        alt = home_down_m - max(float(start[2]), float(target[2]))
        seg = LineString([tuple(start[:2]), tuple(target[:2])]) if np.any(start[:2] != target[:2]) else None
        if seg is None:
            return target if self.inside(target, home_down_m) < 0 else start.copy()
        best = 1.0
        for i in self._blocking(alt):
            g = self._grown[i]
            if not g.intersects(seg):
                continue
            if g.contains(Point(tuple(start[:2]))):
                if g.contains(Point(tuple(target[:2]))) or g.exterior.distance(Point(tuple(target[:2]))) < 1e-9:
                    best = 0.0  # stays inside: no horizontal progress allowed
                continue  # leaving the grown footprint is allowed
            cut = seg.intersection(g.exterior)
            pts = [cut] if cut.geom_type == "Point" else list(getattr(cut, "geoms", []))
            for q in pts:
                f = seg.project(q, normalized=True)
                best = min(best, max(f - 1e-3, 0.0))
        if best >= 1.0:
            return target
        self.clamped += 1
        out = start + best * (target - start)
        out[2] = target[2]
        return out
