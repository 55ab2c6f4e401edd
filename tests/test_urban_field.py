"""Urban mean wind field on small grids: mass balance, cube wake, canyon vortex, sampling.

Wind = air-mass velocity NED; heights above ground h = -z. The validation scenes blow from the
north, so the along-wind component is -north and the air moves toward -x.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from sitl.world.urban import (
    BoxBuilding,
    GridSpec,
    LogWindProfile,
    PolygonBuilding,
    UrbanScene,
    UrbanWindField,
    isolated_cube_scene,
    solve_urban_wind,
    street_canyon_scene,
    urban_wind_mean,
)
from urbanflow.parameterizations import ZONE_CAVITY, ZONE_ROOFTOP, ZONE_UPWIND_VORTEX, ZONE_WAKE

H = 6.0  # small cube: 66 x 42 x 24 cells of 1 m
DIV_BOUND = 1e-3  # max |div| in units of U_ref / dx


@pytest.fixture(scope="module")
def cube() -> UrbanWindField:
    return solve_urban_wind(isolated_cube_scene(height_m=H, spacing_m=1.0))


@pytest.fixture(scope="module")
def canyon() -> UrbanWindField:
    return solve_urban_wind(street_canyon_scene(height_m=H, spacing_m=1.0))


@njit(cache=True)
def _sample_all(points, *args):  # type: ignore[no-untyped-def]
    """The simulator's way: one point at a time from compiled code."""
    out = np.empty_like(points)
    for k in range(points.shape[0]):
        out[k] = urban_wind_mean(points[k], *args)
    return out


def _line(x0: float, x1: float, y: float, h: float, step: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    xs = np.arange(x0, x1, -step)
    return xs, np.column_stack([xs, np.full_like(xs, y), np.full_like(xs, -h)])


def test_mass_consistency(cube: UrbanWindField, canyon: UrbanWindField) -> None:
    for field in (cube, canyon):
        assert field.max_divergence_ratio() < DIV_BOUND
        assert field.stats is not None and field.stats.relative_residual < 1e-6
        solid = field.cell_building >= 0
        # No flow through building faces or the ground.
        assert np.all(field.u_n[:-1][solid] == 0) and np.all(field.u_n[1:][solid] == 0)
        assert np.all(field.w_d[:, :, 0] == 0)


def test_cube_lee_cavity_reattaches_between_1_and_2_h(cube: UrbanWindField) -> None:
    lee = 7.0 * H  # the cube's south (lee) face
    xs, pts = _line(lee - 0.05, 0.0, 3.5 * H, 0.5)
    along = -cube.mean(pts)[:, 0]
    assert along[0] < 0.0  # reversed right behind the cube
    first_forward = int(np.argmax(along > 0.0))
    reattach_h = (lee - xs[first_forward]) / H
    assert 1.0 <= reattach_h <= 2.0, reattach_h
    assert np.all(along[first_forward : first_forward + 40] > 0.0)  # and stays attached after


def test_cube_upwind_reversal_and_roof_speed_up(cube: UrbanWindField) -> None:
    front = 8.0 * H
    xs, pts = _line(front + 0.5 * H, front + 0.05, 3.5 * H, 0.5)
    along = -cube.mean(pts)[:, 0]
    assert along.min() < -0.3  # reversed flow at the ground just upwind of the windward face
    assert along[0] > 0.0  # forward again half a height upwind
    above = np.array([7.5 * H, 3.5 * H, -1.3 * H])
    speed = np.linalg.norm(cube.mean(above))
    assert speed > 1.1 * float(cube.scene.wind.speed_at(1.3 * H))


def test_zones_present(cube: UrbanWindField) -> None:
    zones = set(np.unique(cube.zone).tolist())
    assert {ZONE_CAVITY, ZONE_WAKE, ZONE_UPWIND_VORTEX, ZONE_ROOFTOP, -1} <= zones


def test_zero_inside_buildings_and_log_profile_outside_grid(cube: UrbanWindField) -> None:
    inside = np.array([[7.5 * H, 3.5 * H, -0.5 * H], [7.01 * H, 3.01 * H, -0.01], [7.99 * H, 3.99 * H, -0.99 * H]])
    assert np.all(cube.mean(inside) == 0.0)
    assert cube.inside(inside).all()
    w = cube.scene.wind
    for p in ([-5.0, 10.0, -3.0], [30.0, 500.0, -8.0], [30.0, 10.0, -5.0 * H]):
        v = cube.mean(np.array(p))
        assert v == pytest.approx([-float(w.speed_at(-p[2])), 0.0, 0.0], abs=1e-12)
    assert np.all(cube.mean(np.array([30.0, 10.0, 0.5])) == 0.0)  # below ground


def test_far_field_matches_upstream_profile(cube: UrbanWindField) -> None:
    # Upstream corner of the grid, away from the cube: within 3 % of the log profile, also
    # between cell centres and below the first one (log-law aware vertical interpolation).
    for h in (0.3, 1.0, 3.0, 10.0):
        v = cube.mean(np.array([10.8 * H, 0.3 * H, -h]))
        assert v[0] == pytest.approx(-float(cube.scene.wind.speed_at(h)), rel=0.03)


def test_street_canyon_vortex(canyon: UrbanWindField) -> None:
    x_down = 6.0 * H  # downwind block's windward (north) face; the canyon is x_down .. x_down + H
    y = 5.0 * H
    mid = canyon.mean(np.array([x_down + 0.5 * H, y, -0.2 * H]))
    assert -mid[0] < -0.5  # reversed flow near street level
    near_down = canyon.mean(np.array([x_down + 0.1 * H, y, -0.5 * H]))
    near_up = canyon.mean(np.array([x_down + 0.9 * H, y, -0.5 * H]))
    assert near_down[2] > 0.5  # downward (NED +) along the downwind block's windward face
    assert near_up[2] < -0.5  # upward along the upwind block's lee face
    above = canyon.mean(np.array([x_down + 0.5 * H, y, -1.5 * H]))
    assert -above[0] > 2.0  # skimming flow above the roofs


def test_no_buildings_is_the_log_profile_from_the_from_direction() -> None:
    grid = GridSpec(0.0, 0.0, 40.0, 40.0, 20.0, 2.0)
    field = solve_urban_wind(UrbanScene((), LogWindProfile(7.0, 45.0, 10.0, 0.1), grid))
    assert field.max_divergence_ratio() < 1e-12
    pts = np.array([[13.0, 21.0, -h] for h in np.arange(0.05, 25.0, 0.7)])
    speeds = field.scene.wind.speed_at(-pts[:, 2])
    expected = np.column_stack([-speeds * math.cos(math.pi / 4), -speeds * math.sin(math.pi / 4), 0 * speeds])
    assert field.mean(pts) == pytest.approx(expected, abs=1e-9)


def test_rotated_and_polygon_buildings_oblique_wind() -> None:
    buildings = (
        BoxBuilding(30.0, 30.0, 16.0, 8.0, 10.0, rotation_deg=30.0),
        PolygonBuilding(((44.0, 50.0), (60.0, 50.0), (60.0, 56.0), (50.0, 56.0), (50.0, 66.0), (44.0, 66.0)), 8.0),
    )
    scene = UrbanScene(buildings, LogWindProfile(5.0, 45.0, 10.0, 0.1), GridSpec(0.0, 0.0, 90.0, 90.0, 30.0, 1.5))
    field = solve_urban_wind(scene)
    assert field.max_divergence_ratio() < DIV_BOUND
    assert {ZONE_CAVITY, ZONE_WAKE} <= set(np.unique(field.zone).tolist())
    # Some reversed flow (against the wind direction) in the lee of the rotated block.
    e = np.array(scene.wind.direction_ned)
    pts = np.array([[30.0 + d * e[0], 30.0 + d * e[1], -1.0] for d in np.arange(9.0, 20.0, 0.5)])
    assert (field.mean(pts)[:, :2] @ e).min() < 0.0


def test_sampling_many_single_and_njit_agree(cube: UrbanWindField) -> None:
    rng = np.random.default_rng(101)
    pts = np.column_stack([rng.uniform(-5, 70, 500), rng.uniform(-5, 50, 500), -rng.uniform(-1, 30, 500)])
    many = cube.mean(pts)
    single = np.array([cube.mean(p) for p in pts])
    assert np.array_equal(many, single)
    assert np.array_equal(_sample_all(pts, *cube.kernel_args()), many)


def test_non_finite_positions_give_nan(cube: UrbanWindField) -> None:
    bad = np.array([[np.nan, 10.0, -2.0], [10.0, np.inf, -2.0], [10.0, 10.0, -np.inf]])
    assert np.isnan(cube.mean(bad)).all()
    assert np.isnan(cube.turbulence_multiplier_at(bad)).all()
    assert not cube.inside(bad).any()
    with pytest.raises(ValueError, match=r"shape \(3,\) or \(N, 3\)"):
        cube.mean(np.zeros((2, 2)))


def test_turbulence_multiplier(cube: UrbanWindField) -> None:
    w = cube.scene.wind
    free = cube.turbulence_multiplier_at(np.array([[10.5 * H, 0.5 * H, -h] for h in (1.0, 3.0, 12.0)]))
    assert free == pytest.approx(1.0, rel=0.03)  # undisturbed flow: today's turbulence
    assert cube.turbulence_multiplier_at(np.array([[-10.0, 0.0, -3.0]]))[0] == 1.0  # outside the grid
    cavity = cube.turbulence_multiplier_at(np.array([[6.7 * H, 3.5 * H, -0.3 * H]]))[0]
    u_h = float(w.speed_at(H))
    assert cavity >= 0.99 * cube.scene.options.wake_turbulence_enhancement * u_h / w.speed_m_s
    assert cube.turbulence_multiplier_at(np.array([[7.5 * H, 3.5 * H, -0.5 * H]]))[0] == 0.0
    assert np.all(cube.turbulence_multiplier[cube.cell_building >= 0] == 0.0)
