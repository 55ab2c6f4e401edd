"""Shortest horizontal paths around buildings: a visibility graph over their inflated footprints.

The safety supervisor (:mod:`mission.safety_route`) flies a setpoint that a building blocks around
it along such a path. A building's footprint inflated by ``clearance_m`` is the region the path
must not enter (its distance to the footprint is at least the clearance); the shortest path in
the plane around such regions runs along straight segments between their corners, so the graph's
nodes are the corners of the footprints inflated (mitred) slightly more than the clearance, its
edges the pairs of nodes that see each other, and a query adds the start and the goal and runs
Dijkstra (scipy). Overlapping inflated footprints merge (their union is the obstacle), so a
courtyard closed by buildings is unreachable from outside and a goal in it is replaced by the
nearest reachable point.

Buildings count at an altitude when the vehicle there is below their roof plus the clearance;
one graph is built per set of blocking buildings and cached. Plain deterministic code without
I/O (shapely for the geometry). Units m, frame local NED (north, east); altitudes above home.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy.sparse.csgraph import dijkstra
from shapely import LineString, Point, Polygon, prepare
from shapely.ops import nearest_points, unary_union

from mission.obstacles import Obstacles

#: Nodes sit this much outside the clearance, so that edges along an inflated footprint's side do
#: not touch the region they must stay out of (m).
NODE_SLACK_M = 0.05
#: How far a ray is followed when looking for the far side of what blocks it (m).
RAY_LENGTH_M = 300.0


@dataclass(frozen=True)
class Route:
    """A path around buildings: ``waypoints`` (K, 2) north/east m from the start (row 0) to the goal
    (last row), ``length_m`` its length; ``goal_moved``: the requested goal was inside an inflated
    footprint (or unreachable) and the path ends at the nearest reachable point instead."""

    waypoints: np.ndarray
    length_m: float
    goal_moved: bool

    def point_at(self, s_m: float) -> np.ndarray:
        """The point ``s_m`` metres along the path (clipped to its ends), north/east m."""
        w = self.waypoints
        seg = np.hypot(*(w[1:] - w[:-1]).T) if len(w) > 1 else np.zeros(0)
        s = float(s_m)
        for i, ln in enumerate(seg):
            if s <= ln and ln > 0.0:
                return w[i] + (w[i + 1] - w[i]) * (s / ln)
            s -= float(ln)
        return w[-1].copy()


class _Graph:
    """The visibility graph of one set of inflated footprints (see the module docstring)."""

    def __init__(self, footprints: list[Polygon], clearance_m: float) -> None:
        # The region to stay out of: a hair inside the clearance, so a path exactly at it is free.
        self.solid = unary_union([f.buffer(max(clearance_m - 1e-3, 0.0)) for f in footprints])
        prepare(self.solid)
        # Where escapes and moved goals go: just outside the clearance (reachable, free).
        self.outer = unary_union([f.buffer(clearance_m + NODE_SLACK_M) for f in footprints])
        self.outer_edge = self.outer.boundary
        corners: list[tuple[float, float]] = []
        for f in footprints:
            g = f.buffer(clearance_m + NODE_SLACK_M, join_style="mitre", mitre_limit=2.0)
            corners += list(g.exterior.coords)[:-1]
        pts = np.array(corners, dtype=float).reshape(-1, 2)
        keep = ~shapely.intersects(self.solid, shapely.points(pts)) if len(pts) else np.zeros(0, bool)
        self.nodes = pts[keep]
        n = len(self.nodes)
        w = np.full((n, n), np.inf)
        if n > 1:
            i, j = np.triu_indices(n, 1)
            vis = self.visible(self.nodes[i], self.nodes[j])
            d = np.hypot(*(self.nodes[i] - self.nodes[j]).T)
            w[i[vis], j[vis]] = d[vis]
            w[j[vis], i[vis]] = d[vis]
        self.weights = w

    def visible(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool (M,): the segments a[k]-b[k] ((M, 2) each) stay out of the solid region."""
        a, b = np.atleast_2d(a), np.atleast_2d(b)
        b = np.broadcast_to(b, a.shape) if len(b) == 1 else b
        a = np.broadcast_to(a, b.shape) if len(a) == 1 else a
        lines = shapely.linestrings(np.stack([a, b], axis=1))
        return np.asarray(~shapely.intersects(self.solid, lines), dtype=bool)

    def free(self, p: np.ndarray) -> bool:
        return not self.solid.intersects(Point(float(p[0]), float(p[1])))

    def nearest_free(self, p: np.ndarray) -> np.ndarray:
        """``p`` itself when free, else the nearest point just outside the clearance."""
        if self.free(p):
            return np.asarray(p, float).copy()
        q = nearest_points(self.outer_edge, Point(float(p[0]), float(p[1])))[0]
        return np.array([q.x, q.y])


class Router:
    """Paths around the buildings of ``obstacles`` kept ``clearance_m`` away (see the module docstring).

    Args:
        obstacles: the buildings (footprints, roof heights above home).
        clearance_m: distance every path keeps from a footprint (m); the supervisor plans with more
            than its hard margin, so that tracking errors stay outside the margin.
    """

    def __init__(self, obstacles: Obstacles, clearance_m: float) -> None:
        if not (np.isfinite(clearance_m) and clearance_m >= 0.0):
            raise ValueError(f"route clearance {clearance_m!r}: must be a finite number >= 0 (m)")
        self.obstacles = obstacles
        self.clearance_m = float(clearance_m)
        self._shapes = [Polygon(b.footprint) for b in obstacles.buildings]
        self._graphs: dict[tuple[int, ...], _Graph | None] = {}

    def graph(self, altitude_m: float) -> _Graph | None:
        """The graph of the buildings that block at ``altitude_m`` above home (None: none do)."""
        key = tuple(i for i, b in enumerate(self.obstacles.buildings) if altitude_m < b.height_m + self.clearance_m)
        if key not in self._graphs:
            self._graphs[key] = _Graph([self._shapes[i] for i in key], self.clearance_m) if key else None
        return self._graphs[key]

    def free_segment(self, a: np.ndarray, b: np.ndarray, altitude_m: float) -> bool:
        """The straight segment a-b (north/east m) keeps the clearance from every blocking building."""
        g = self.graph(altitude_m)
        return g is None or bool(g.visible(np.asarray(a, float)[:2], np.asarray(b, float)[:2])[0])

    def free_point(self, p: np.ndarray, altitude_m: float) -> bool:
        g = self.graph(altitude_m)
        return g is None or g.free(np.asarray(p, float)[:2])

    def nearest_free(self, p: np.ndarray, altitude_m: float) -> np.ndarray:
        """The nearest point to ``p`` (north/east m) that keeps the clearance (``p`` if it does)."""
        g = self.graph(altitude_m)
        q = np.asarray(p, float)[:2]
        return q.copy() if g is None else g.nearest_free(q)

    def beyond(self, start: np.ndarray, direction: np.ndarray, altitude_m: float,
               past_m: float = 2.0) -> np.ndarray | None:  # fmt: skip
        """Where a straight flight from ``start`` along ``direction`` (north/east) would come out on
        the far side of the first inflated building it enters, ``past_m`` beyond it (moved to the
        nearest free point if that is inside another one); None when nothing blocks the ray."""
        g = self.graph(altitude_m)
        s = np.asarray(start, float)[:2]
        d = np.asarray(direction, float)[:2]
        nd = float(np.hypot(*d))
        if g is None or nd == 0.0:
            return None
        d = d / nd
        ray = LineString([tuple(s), tuple(s + RAY_LENGTH_M * d)])
        cut = ray.intersection(g.solid)
        if cut.is_empty:
            return None
        pieces = [cut] if cut.geom_type == "LineString" else [p for p in getattr(cut, "geoms", []) if p.length > 0]
        if not pieces:
            return None
        first = min(pieces, key=lambda p: min(ray.project(Point(c)) for c in p.coords))
        s_exit = max(ray.project(Point(c)) for c in first.coords)
        return g.nearest_free(s + min(s_exit + past_m, RAY_LENGTH_M) * d)

    def route(self, start: np.ndarray, goal: np.ndarray, altitude_m: float) -> Route:
        """The shortest path from ``start`` to ``goal`` (north/east m) keeping the clearance.

        A start inside the clearance (a gust, tracking error) first leaves it by the shortest way
        out; a goal inside it, or one that cannot be reached (a closed courtyard), is replaced by
        the nearest reachable point (``goal_moved``)."""
        s0 = np.asarray(start, float)[:2].copy()
        goal_in = np.asarray(goal, float)[:2]
        g = self.graph(altitude_m)
        if g is None:
            return Route(np.array([s0, goal_in]), float(np.hypot(*(goal_in - s0))), False)
        head = [s0]
        s = g.nearest_free(s0)
        if np.any(s != s0):
            head.append(s)
        goal = g.nearest_free(goal_in)
        moved = bool(np.any(goal != goal_in))
        path = self._shortest(g, s, goal)
        if path is None:  # goal enclosed: go to the reachable node nearest to it, then as close as visible
            path, moved = self._nearest_reachable(g, s, goal), True
        pts = np.array(head + [p for p in path[1:]]) if len(path) > 1 else np.array(head)
        if len(pts) == 1:
            pts = np.array([s0, s0])
        length = float(np.sum(np.hypot(*(pts[1:] - pts[:-1]).T)))
        return Route(pts, length, moved)

    @staticmethod
    def _shortest(g: _Graph, s: np.ndarray, goal: np.ndarray) -> list[np.ndarray] | None:
        """Dijkstra over the graph plus the start (index n) and the goal (n + 1); None: unreachable."""
        if bool(g.visible(s, goal)[0]):
            return [s, goal]
        n = len(g.nodes)
        if n == 0:
            return None
        w = np.full((n + 2, n + 2), np.inf)
        w[:n, :n] = g.weights
        for k, p in ((n, s), (n + 1, goal)):
            vis = g.visible(np.broadcast_to(p, g.nodes.shape), g.nodes)
            d = np.hypot(*(g.nodes - p).T)
            w[k, :n] = np.where(vis, d, np.inf)
            w[:n, k] = w[k, :n]
        dense = np.where(np.isfinite(w), w, 0.0)
        dist, pred = dijkstra(dense, directed=False, indices=n, return_predecessors=True)
        if not np.isfinite(dist[n + 1]):
            return None
        order = [n + 1]
        while order[-1] != n:
            order.append(int(pred[order[-1]]))
        pts = {n: s, n + 1: goal}
        return [pts[k] if k in pts else g.nodes[k] for k in reversed(order)]

    @staticmethod
    def _nearest_reachable(g: _Graph, s: np.ndarray, goal: np.ndarray) -> list[np.ndarray]:
        """A path to the reachable node nearest the goal (the start itself if no node is reachable)."""
        n = len(g.nodes)
        if n == 0:
            return [s]
        w = np.full((n + 1, n + 1), np.inf)
        w[:n, :n] = g.weights
        vis = g.visible(np.broadcast_to(s, g.nodes.shape), g.nodes)
        w[n, :n] = np.where(vis, np.hypot(*(g.nodes - s).T), np.inf)
        w[:n, n] = w[n, :n]
        dist, pred = dijkstra(np.where(np.isfinite(w), w, 0.0), directed=False, indices=n, return_predecessors=True)
        reach = [k for k in range(n) if np.isfinite(dist[k])]
        if not reach:
            return [s]
        best = min(reach, key=lambda k: (float(np.hypot(*(g.nodes[k] - goal))), k))
        order = [best]
        while order[-1] != n:
            order.append(int(pred[order[-1]]))
        return [s if k == n else g.nodes[k] for k in reversed(order)]
