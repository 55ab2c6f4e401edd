"""Routing around buildings (issue 20): the visibility-graph router and the supervisor's building
guard, on plain geometry (no simulator: a point vehicle follows the guard's setpoints)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely import LineString, Point, Polygon

from mission.obstacles import Building, Obstacles
from mission.routing import Router
from mission.safety import SafetyLimits, Supervisor
from mission.safety_route import BuildingGuard
from sitl.scenario import load_scenario


def box(n: float, e: float, half_n: float, half_e: float, height: float = 15.0, name: str = "") -> Building:
    fp = np.array([[n - half_n, e - half_e], [n + half_n, e - half_e], [n + half_n, e + half_e],
                   [n - half_n, e + half_e]])
    return Building(fp, height, name)


def clearance_of(path: np.ndarray, buildings: list[Building]) -> float:
    """Smallest horizontal distance of a polyline (K, 2) from any footprint (m)."""
    line = LineString(path) if len(path) > 1 else Point(path[0])
    return min(Polygon(b.footprint).distance(line) for b in buildings)


def test_a_target_behind_a_building_is_reached_by_a_path_that_never_enters_its_inflated_footprint() -> None:
    b = [box(0.0, 0.0, 10.0, 10.0)]
    r = Router(Obstacles(b), clearance_m=4.0)
    start, goal = np.array([-30.0, 2.0]), np.array([30.0, -1.0])
    assert not r.free_segment(start, goal, 3.0)
    route = r.route(start, goal, 3.0)
    assert np.allclose(route.waypoints[0], start) and np.allclose(route.waypoints[-1], goal)
    assert not route.goal_moved
    assert clearance_of(route.waypoints, b) >= 4.0 - 1e-3
    # The shortest way round a 20 m block kept 4 m clear: over its (mitred) corners, not a wide berth.
    straight = float(np.hypot(*(goal - start)))
    assert straight < route.length_m < straight + 2 * 14.0
    # Every point of the path, sampled, is outside the inflated footprint.
    for s in np.linspace(0.0, route.length_m, 200):
        p = route.point_at(s)
        assert Polygon(b[0].footprint).distance(Point(*p)) >= 4.0 - 1e-3


def test_paper_s4_route_from_the_start_to_the_source_keeps_clear_of_all_six_buildings() -> None:
    sc = load_scenario("paper-s4")
    assert sc.urban is not None and sc.plume is not None
    obs = Obstacles.from_buildings(sc.urban.buildings)
    r = Router(obs, clearance_m=4.0)
    start = np.asarray(sc.start.position_ned[:2], float)
    src = np.asarray(sc.plume.plume.sources[0].position_ned[:2], float)
    route = r.route(start, src, 3.0)
    assert np.allclose(route.waypoints[-1], src) and not route.goal_moved
    assert clearance_of(route.waypoints, obs.buildings) >= 4.0 - 1e-3
    assert route.length_m > float(np.hypot(*(src - start)))  # the straight line runs through two blocks
    # Above every roof (20 m + the clearance) nothing is in the way.
    assert r.free_segment(start, src, 25.0)
    assert len(r.route(start, src, 25.0).waypoints) == 2


def test_a_goal_inside_a_building_is_replaced_by_the_nearest_reachable_point() -> None:
    b = [box(0.0, 0.0, 10.0, 5.0)]
    r = Router(Obstacles(b), clearance_m=3.0)
    route = r.route(np.array([-30.0, 0.0]), np.array([1.0, 4.0]), 3.0)  # inside, near the east face (e = 5)
    assert route.goal_moved
    end = route.waypoints[-1]
    # Out by the east face: the nearest side, just outside the clearance.
    assert end[1] == pytest.approx(5.0 + 3.0, abs=0.1) and end[0] == pytest.approx(1.0, abs=0.1)
    assert clearance_of(route.waypoints, b) >= 3.0 - 1e-3


def test_a_closed_courtyard_is_not_entered_and_its_goal_moves_to_the_nearest_point_outside() -> None:
    # Four blocks in a ring with 4 m gaps: inflated by 3 m they merge, the courtyard is closed.
    ring = [box(0.0, 15.0, 15.0, 2.5), box(0.0, -15.0, 15.0, 2.5),
            box(15.0, 0.0, 2.5, 10.5), box(-15.0, 0.0, 2.5, 10.5)]
    r = Router(Obstacles(ring), clearance_m=3.0)
    centre = np.array([0.0, 0.0])
    assert r.free_point(centre, 3.0)  # 10 m from every wall: free, but unreachable
    route = r.route(np.array([-50.0, 3.0]), centre, 3.0)
    assert route.goal_moved
    assert clearance_of(route.waypoints, ring) >= 3.0 - 1e-3
    end = route.waypoints[-1]
    assert max(abs(end[0]), abs(end[1])) > 17.5  # outside the ring


def test_a_start_inside_the_clearance_leaves_it_by_the_shortest_way() -> None:
    b = [box(0.0, 0.0, 10.0, 10.0)]
    r = Router(Obstacles(b), clearance_m=4.0)
    start = np.array([-11.0, 0.0])  # 1 m from the south face
    route = r.route(start, np.array([30.0, 0.0]), 3.0)
    assert route.waypoints[1][0] == pytest.approx(-14.05, abs=0.05) and route.waypoints[1][1] == pytest.approx(0.0)
    assert clearance_of(route.waypoints[1:], b) >= 4.0 - 1e-3


def fly(guard: BuildingGuard, heading: object, t_end: float, start: np.ndarray, dt: float = 0.1
        ) -> tuple[np.ndarray, list[np.ndarray]]:  # fmt: skip
    """A point vehicle that flies the guard's setpoints: a strategy's carrot 2 m ahead along
    ``heading(t)`` (unit north/east) at 2.5 m/s in, the guard's setpoint out, the vehicle's
    velocity the feed-forward plus 1/s of position error (a position-velocity controller)."""
    pos, vel = start.astype(float).copy(), np.zeros(3)
    track = [pos.copy()]
    for k in range(int(t_end / dt)):
        h = np.asarray(heading(k * dt), float)  # type: ignore[operator]
        sp_vel = np.array([2.5 * h[0], 2.5 * h[1], 0.0])
        sp_pos = np.array([pos[0] + 2.0 * h[0], pos[1] + 2.0 * h[1], -3.0])
        p, v, _ = guard.apply(sp_pos, sp_vel, pos, vel)
        assert p is not None and v is not None
        vel = v + 1.0 * (p - pos)
        vel[:2] *= min(1.0, 4.0 / max(float(np.hypot(*vel[:2])), 1e-9))
        pos = pos + vel * dt
        track.append(pos.copy())
    return pos, track


@pytest.mark.parametrize("zigzag", [False, True])
def test_the_guard_flies_a_heading_into_a_wall_around_the_building(zigzag: bool) -> None:
    """Straight at the middle of a 30 m wide block, or zig-zagging at +-30 deg about that line (legs
    that turn every 2 s: a guard that re-planned each leg from scratch dithers at the wall, measured)."""
    b = [box(0.0, 0.0, 5.0, 15.0)]
    guard = BuildingGuard(Obstacles(b, margin_m=3.0), home_down_m=0.0)

    def heading(t: float) -> np.ndarray:
        if not zigzag:
            return np.array([1.0, 0.0])
        a = math.radians(30.0) * (1 if int(t / 2.0) % 2 == 0 else -1)
        return np.array([math.cos(a), math.sin(a)])

    end, track = fly(guard, heading, 30.0, np.array([-25.0, 0.0, -3.0]))
    assert end[0] > 20.0  # got past the building (its upwind face is at north 5) within 30 s
    assert clearance_of(np.array(track)[:, :2], b) >= 3.0  # never inside the hard margin
    assert guard.detours >= 1 and guard.detour_ticks > 10


def test_a_position_target_inside_a_building_ends_at_the_nearest_reachable_point_and_holds() -> None:
    b = [box(0.0, 0.0, 5.0, 15.0)]
    guard = BuildingGuard(Obstacles(b, margin_m=3.0), home_down_m=0.0)
    pos, vel = np.array([-20.0, 3.0, -3.0]), np.zeros(3)
    target = np.array([3.0, 2.0, -3.0])  # inside, nearest face: the north one (n = 5)
    for _ in range(400):
        p, v, _ = guard.apply(target, None, pos, vel)
        assert p is not None and v is not None
        vel = v + 1.0 * (p - pos)
        pos = pos + vel * 0.1
        assert Polygon(b[0].footprint).distance(Point(pos[0], pos[1])) >= 3.0
    assert pos[0] == pytest.approx(5.0 + 4.05, abs=0.3) and pos[1] == pytest.approx(2.0, abs=0.5)


def test_the_supervisor_never_sends_a_setpoint_whose_path_enters_a_building() -> None:
    b = [box(0.0, 0.0, 10.0, 10.0)]
    obs = Obstacles(b, margin_m=3.0)
    sup = Supervisor(SafetyLimits(), np.zeros(3), obs)
    rng = np.random.default_rng(5)
    for _ in range(300):
        cur = np.array([*rng.uniform(-40.0, 40.0, 2), -3.0])
        if obs.inside(cur) >= 0:
            continue
        sp = np.array([*rng.uniform(-40.0, 40.0, 2), -3.0])
        pos, _ = sup.clamp(sp, rng.normal(0.0, 2.0, 3) * [1, 1, 0], cur, np.zeros(3))
        assert pos is not None
        assert Polygon(b[0].footprint).distance(LineString([cur[:2], pos[:2]])) >= 3.0 - 1e-6


def test_paper_s4_street_puts_the_source_in_the_street_between_two_blocks_reachable_along_it() -> None:
    sc, base = load_scenario("paper-s4-street"), load_scenario("paper-s4")
    assert sc.urban is not None and sc.plume is not None and base.urban is not None
    assert sc.urban.buildings == base.urban.buildings and sc.wind == base.wind  # only the source moved
    obs = Obstacles.from_buildings(sc.urban.buildings)
    src = np.asarray(sc.plume.plume.sources[0].position_ned[:2], float)
    gaps = {b.name: Polygon(b.footprint).distance(Point(*src)) for b in obs.buildings}
    assert gaps["block-5"] == pytest.approx(10.0, abs=0.05) and gaps["block-6"] == pytest.approx(10.0, abs=0.05)
    assert min(gaps.values()) == pytest.approx(10.0, abs=0.05)
    start = np.asarray(sc.start.position_ned[:2], float)
    route = Router(obs, clearance_m=4.0).route(start, src, 3.0)
    assert not route.goal_moved and clearance_of(route.waypoints, obs.buildings) >= 4.0 - 1e-3
