"""Geofence: inclusion/exclusion polygons and circles (horizontal, NED metres), enforced in lockstep.

:meth:`Geofence.on_mode_tick` is registered as a ``Simulation.step_hooks`` entry, so the check
runs at every mode tick with the true position, like PX4's geofence in the flight controller.
A breach while flying (armed, off the ground) triggers ``action`` once (PX4 GF_ACTION:
0 none, 1 warning, 2 hold, 3 return to launch, 4 land) and a STATUSTEXT; the breach re-arms
when the vehicle is back inside.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from sitl.simulation import Simulation

GF_NONE, GF_WARN, GF_HOLD, GF_RTL, GF_LAND = 0, 1, 2, 3, 4


def _inside_polygon(p: np.ndarray, poly: np.ndarray) -> bool:
    """Even-odd rule; ``poly`` (K, 2) north/east vertices in m."""
    x, y = float(p[0]), float(p[1])
    inside = False
    n = len(poly)
    for i in range(n):
        x1, y1 = poly[i]
        x2, y2 = poly[(i + 1) % n]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


class Geofence:
    """Zones in the NED horizontal plane; empty = no fence."""

    def __init__(self) -> None:
        self.polygons: list[tuple[np.ndarray, bool]] = []  # (vertices (K, 2) m, inclusion)
        self.circles: list[tuple[np.ndarray, float, bool]] = []  # (centre (2,) m, radius m, inclusion)
        self.action = GF_HOLD
        self.breached = False
        self.breaches = 0

    def add_polygon(self, pts: np.ndarray, inclusion: bool) -> None:
        self.polygons.append((np.asarray(pts, dtype=float), inclusion))

    def add_circle(self, centre: np.ndarray, radius_m: float, inclusion: bool) -> None:
        self.circles.append((np.asarray(centre, dtype=float), float(radius_m), inclusion))

    def load(self, other: Geofence) -> None:
        """Replace the zones (keeps the action setting and the hook registration)."""
        self.polygons = other.polygons
        self.circles = other.circles
        self.breached = False

    @property
    def empty(self) -> bool:
        return not self.polygons and not self.circles

    def violated(self, pos_ned: np.ndarray) -> bool:
        """True if ``pos_ned`` is outside every inclusion zone (when any) or inside an exclusion zone."""
        p = np.asarray(pos_ned[0:2], dtype=float)
        has_incl = False
        in_incl = False
        for poly, incl in self.polygons:
            inside = _inside_polygon(p, poly)
            if incl:
                has_incl = True
                in_incl = in_incl or inside
            elif inside:
                return True
        for c, r, incl in self.circles:
            inside = float(np.hypot(*(p - c))) <= r
            if incl:
                has_incl = True
                in_incl = in_incl or inside
            elif inside:
                return True
        return has_incl and not in_incl

    def on_mode_tick(self, sim: Simulation) -> None:
        if self.empty:
            return
        fc = sim.fc
        bad = self.violated(sim.x[0:3])
        if not bad:
            self.breached = False
            return
        if self.breached or not fc.armed or sim.on_ground:
            return
        self.breached = True
        self.breaches += 1
        if self.action == GF_NONE:
            return
        fc.say("Geofence breached", 4)
        if self.action == GF_HOLD:
            fc.hold()
        elif self.action == GF_RTL:
            fc.rtl()
        elif self.action == GF_LAND:
            fc.land()
