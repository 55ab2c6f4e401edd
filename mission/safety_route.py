"""The safety supervisor's building layer: a setpoint that a building blocks is flown around it.

A strategy's setpoint is either a *heading* (a position carrot a few metres ahead with a velocity
feed-forward, or a bare velocity: the strategy wants to go that way) or a *point* (a position
without velocity: it wants to be there). :class:`BuildingGuard` looks ahead along it: along a
heading as far as the vehicle flies in ``look_ahead_s`` (at the faster of the commanded and its
own speed, so a vehicle that runs ahead of its carrot is still seen coming), to a point all the
way. While that straight flight keeps the route clearance (the hard margin plus
``plan_extra_m``) from every building, the setpoint passes unchanged. When it does not, the guard
picks a detour goal -- for a heading, the far side of the building it points into
(:meth:`mission.routing.Router.beyond`); for a point, the point itself, or the nearest reachable
point when it is inside a building or a closed courtyard -- and replaces the setpoint by a carrot
``carrot_m`` along the shortest path there (:class:`mission.routing.Router`) with the velocity
feed-forward along it, re-planned every tick from where the vehicle is. The goal is kept while
the strategy still points toward it (a zig-zag's legs alternate, but both lead past the building),
so the vehicle gets around instead of dithering at the wall; it is dropped when reached, when the
way ahead is free again (the strategy has its setpoint back), or when the strategy turns away.

Near a wall the velocity component toward it is limited to what stops the vehicle at the hard
margin with ``brake_m_s2`` of deceleration (so turbulence and the autopilot's overshoot do not
carry it in); the same limit applies to setpoints that pass unchanged.

Plain deterministic code without I/O: the in-process and the MAVSDK runner use it alike, through
:class:`mission.safety.Supervisor`. Units SI, NED; altitudes above home.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely import Point, Polygon, prepare
from shapely.geometry.base import BaseGeometry
from shapely.ops import nearest_points, unary_union

from mission.obstacles import Obstacles
from mission.routing import Router


@dataclass(frozen=True)
class GuardConfig:
    """Tuning of :class:`BuildingGuard` (SI units).

    plan_extra_m: detours keep the hard margin plus this from every footprint [m] (room for
        tracking errors before the margin).
    look_ahead_s: a heading is checked this far ahead at the faster of the commanded and the
        vehicle's own horizontal speed [s]; min_look_m: at least this far [m].
    carrot_m: the detour's position setpoint runs this far ahead of the vehicle along the path [m].
    point_speed_m_s: speed along a detour to a position-only setpoint [m/s].
    brake_m_s2: near a wall the speed toward it is limited to sqrt(2 * brake * (distance - margin)) [m/s^2].
    brake_zone_m: the limit applies within this distance of a footprint [m].
    reach_m: a detour goal this close counts as reached [m].
    """

    plan_extra_m: float = 1.0
    look_ahead_s: float = 2.0
    min_look_m: float = 3.0
    carrot_m: float = 2.0
    point_speed_m_s: float = 2.0
    brake_m_s2: float = 0.8
    brake_zone_m: float = 10.0
    reach_m: float = 1.0


class BuildingGuard:
    """Flies blocked setpoints around buildings (see the module docstring).

    Args:
        obstacles: the buildings; their ``margin_m`` is the hard clearance.
        home_down_m: home's down coordinate (altitudes are above it) [m].
        cfg: tuning.
    """

    def __init__(self, obstacles: Obstacles, home_down_m: float, cfg: GuardConfig | None = None) -> None:
        self.cfg = cfg or GuardConfig()
        self.obstacles = obstacles
        self.home_down = float(home_down_m)
        self.router = Router(obstacles, obstacles.margin_m + self.cfg.plan_extra_m)
        self._walls: dict[tuple[int, ...], BaseGeometry | None] = {}
        self._shapes = [Polygon(b.footprint) for b in obstacles.buildings]
        self.goal: np.ndarray | None = None  # the detour goal (north/east m), None: no detour
        self._point: np.ndarray | None = None  # the position target the detour was planned for
        self.detours = 0  # detours started
        self.detour_ticks = 0  # setpoints replaced by a detour's
        self.braked = 0  # setpoints whose speed toward a wall was limited

    def apply(self, pos: np.ndarray | None, vel: np.ndarray | None, current: np.ndarray,
              current_vel: np.ndarray | None = None) -> tuple[np.ndarray | None, np.ndarray | None, bool]:  # fmt: skip
        """The setpoint to send (position m, velocity m/s, NED) and whether it was changed.
        ``current`` / ``current_vel``: the vehicle's position and velocity (NED)."""
        cfg, cur = self.cfg, np.asarray(current, float)
        down = max(float(cur[2]), float(pos[2])) if pos is not None else float(cur[2])
        alt = self.home_down - down
        own = 0.0 if current_vel is None else float(np.hypot(*np.asarray(current_vel, float)[:2]))
        vh = None if vel is None else np.asarray(vel, float)[:2]
        speed = 0.0 if vh is None else float(np.hypot(*vh))
        if speed > 0.05:  # a heading
            assert vh is not None
            d = vh / speed
            ahead = cur[:2] + max(cfg.look_ahead_s * max(speed, own), cfg.min_look_m) * d
            checks = [ahead] if pos is None else [ahead, np.asarray(pos, float)[:2]]
            target = None
        elif pos is not None and float(np.hypot(*(np.asarray(pos, float)[:2] - cur[:2]))) > 0.05:
            target = np.asarray(pos, float)[:2]
            d = (target - cur[:2]) / float(np.hypot(*(target - cur[:2])))
            speed, checks = cfg.point_speed_m_s, [target]
        else:  # hovering in place
            self.goal = None
            return pos, vel, False
        if all(self.router.free_segment(cur[:2], c, alt) for c in checks):
            self.goal = None
            return self._brake(pos, vel, cur, alt)
        self._choose_goal(cur[:2], d, target, alt)
        assert self.goal is not None
        route = self.router.route(cur[:2], self.goal, alt)
        carrot = route.point_at(min(cfg.carrot_m, route.length_m))
        step = carrot - cur[:2]
        dist = float(np.hypot(*step))
        v_h = step / dist * min(speed, math.sqrt(2.0 * cfg.brake_m_s2 * route.length_m)) if dist > 0.05 \
            else np.zeros(2)  # fmt: skip
        z = float(pos[2]) if pos is not None else float(cur[2])
        vz = float(vel[2]) if vel is not None else 0.0
        self.detour_ticks += 1
        return np.array([carrot[0], carrot[1], z]), np.array([v_h[0], v_h[1], vz]), True

    def _choose_goal(self, cur: np.ndarray, d: np.ndarray, target: np.ndarray | None, alt: float) -> None:
        """Keep the detour goal while it still serves the setpoint, else pick a new one."""
        if self.goal is not None:
            to_goal = self.goal - cur
            far = float(np.hypot(*to_goal)) > self.cfg.reach_m
            if target is None:
                same = self._point is None and float(to_goal @ d) > 0.0
            else:
                same = self._point is not None and float(np.hypot(*(self._point - target))) < 1.0
            if not (far and same):
                self.goal = None
        if self.goal is None:
            if target is None:
                goal = self.router.beyond(cur, d, alt)
                # The ray is clear but the carrot is not (it lies off the velocity): to the carrot's free side.
                self.goal = goal if goal is not None else self.router.nearest_free(cur + self.cfg.carrot_m * d, alt)
            else:
                self.goal = self.router.nearest_free(target, alt)
            self._point = None if target is None else target.copy()
            self.detours += 1

    def _wall(self, alt: float) -> BaseGeometry | None:
        """The union of the footprints that block at ``alt`` (prepared), or None."""
        key = tuple(i for i, b in enumerate(self.obstacles.buildings) if alt < b.height_m + self.router.clearance_m)
        if key not in self._walls:
            u = unary_union([self._shapes[i] for i in key]) if key else None
            if u is not None:
                prepare(u)
            self._walls[key] = u
        return self._walls[key]

    def _brake(self, pos: np.ndarray | None, vel: np.ndarray | None, cur: np.ndarray, alt: float
               ) -> tuple[np.ndarray | None, np.ndarray | None, bool]:  # fmt: skip
        """The setpoint with its velocity toward the nearest wall limited (see the module docstring)."""
        wall = self._wall(alt)
        if vel is None or wall is None:
            return pos, vel, False
        here = Point(float(cur[0]), float(cur[1]))
        dist = float(wall.distance(here))
        if dist >= self.cfg.brake_zone_m or dist <= 0.0:
            return pos, vel, False
        q = nearest_points(wall, here)[0]
        away = (cur[:2] - np.array([q.x, q.y])) / dist  # unit normal from the wall to the vehicle
        v = np.asarray(vel, float).copy()
        toward = -float(v[:2] @ away)
        limit = math.sqrt(2.0 * self.cfg.brake_m_s2 * max(dist - self.obstacles.margin_m, 0.0))
        if toward <= limit:
            return pos, vel, False
        v[:2] += (toward - limit) * away
        self.braked += 1
        return pos, v, True
