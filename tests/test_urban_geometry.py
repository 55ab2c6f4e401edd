"""Building geometry kernels: inside tests, reflection of puffs, voxels (NED points, heights = -z)."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from sitl.world.urban import BoxBuilding, BuildingArrays, PolygonBuilding, building_at, inside_many, reflect_many
from urbanflow.geometry import voxelize

# A 10 x 10 m box (north 0..10, east 0..10, 8 m tall), an L-shaped (concave) polygon and a box
# rotated 45 deg centred at (50, 50).
BOX = BoxBuilding(0.0, 0.0, 10.0, 10.0, 8.0, anchor="corner")
ELL = PolygonBuilding(((20.0, 0.0), (40.0, 0.0), (40.0, 8.0), (28.0, 8.0), (28.0, 20.0), (20.0, 20.0)), 12.0)
DIAMOND = BoxBuilding(50.0, 50.0, 10.0, 10.0, 6.0, rotation_deg=45.0)
GEOM = BuildingArrays.from_buildings((BOX, ELL, DIAMOND))


def _inside(points: list[tuple[float, float, float]]) -> list[bool]:
    return inside_many(np.array(points, dtype=np.float64), *GEOM.args()).tolist()


def test_inside_box_heights_and_edges() -> None:
    assert _inside([(5, 5, -1), (5, 5, -7.99), (5, 5, -8.0), (5, 5, -9), (5, 5, 0.5), (5, 11, -1), (-0.1, 5, -1)]) == [
        True, True, False, False, False, False, False,
    ]


def test_inside_concave_polygon() -> None:
    # In the L's foot and its leg, not in the notch between them.
    assert _inside([(35, 4, -5), (24, 15, -5), (35, 15, -5), (30, 10, -11.9), (30, 10, -12.1)]) == [
        True, True, False, False, False,
    ]
    assert _inside([(24, 4, -11.9)]) == [True]


def test_inside_rotated_box() -> None:
    h = 5.0 * np.sqrt(2.0)  # half-diagonal of the diamond
    assert _inside([(50 + h - 0.05, 50, -1), (50 + h + 0.05, 50, -1), (50 + 3.6, 50 + 3.6, -1), (53.4, 53.4, -1)]) == [
        True, False, False, True,
    ]


def test_building_at_returns_index_and_works_in_njit() -> None:
    @njit
    def crashed(x: float, y: float, z: float, verts, offsets, heights, bbox) -> int:
        return building_at(x, y, -z, verts, offsets, heights, bbox)

    assert crashed(5.0, 5.0, -2.0, *GEOM.args()) == 0
    assert crashed(24.0, 15.0, -2.0, *GEOM.args()) == 1
    assert crashed(50.0, 50.0, -2.0, *GEOM.args()) == 2
    assert crashed(15.0, 15.0, -2.0, *GEOM.args()) == -1


def _reflect(point: tuple[float, float, float], prev: tuple[float, float, float]) -> tuple[np.ndarray, int]:
    out, moved = reflect_many(np.array([point], dtype=np.float64), np.array([prev], dtype=np.float64), *GEOM.args())
    return out[0], moved


def test_reflect_off_a_wall_is_specular() -> None:
    # Moving south into the box's north wall (x = 10) from x = 12 to x = 9: ends at x = 11.
    p, moved = _reflect((9.0, 5.0, -3.0), (12.0, 4.0, -3.0))
    assert moved == 1
    assert p == pytest.approx([11.0, 5.0, -3.0])
    # Into the west wall (y = 0) of the box moving east.
    p, _ = _reflect((3.0, 0.5, -2.0), (3.0, -1.0, -2.0))
    assert p == pytest.approx([3.0, -0.5, -2.0])


def test_reflect_off_the_roof_and_a_slanted_wall() -> None:
    p, _ = _reflect((5.0, 5.0, -7.0), (5.0, 5.0, -9.0))  # down through the roof at 8 m
    assert p == pytest.approx([5.0, 5.0, -9.0])
    # The diamond's north-east face has outward normal (1, 1)/sqrt(2); a step along -x into it
    # is mirrored to a step along +y.
    h = 5.0 * np.sqrt(2.0)
    start = np.array([50.0 + h / 2 + 1.0, 50.0 + h / 2, -1.0])
    p, _ = _reflect(tuple(start - [2.0, 0.0, 0.0]), tuple(start))
    assert p == pytest.approx(start + [0.0, 0.0, 0.0] + [-1.0, 1.0, 0.0], abs=1e-9)
    assert not _inside([tuple(p)])[0]


def test_reflect_leaves_outside_points_and_always_ends_outside() -> None:
    rng = np.random.default_rng(100)
    prev = np.column_stack([rng.uniform(-5, 60, 4000), rng.uniform(-5, 60, 4000), -rng.uniform(0, 14, 4000)])
    pts = prev + rng.normal(0.0, 3.0, prev.shape)
    pts[:, 2] = np.minimum(pts[:, 2], 0.0)
    outside_before = ~inside_many(pts, *GEOM.args())
    prev_out = ~inside_many(prev, *GEOM.args())
    pts, prev = pts[prev_out], prev[prev_out]
    outside_before = outside_before[prev_out]
    out, moved = reflect_many(pts, prev, *GEOM.args())
    assert moved == int((~outside_before).sum()) > 50
    assert np.array_equal(out[outside_before], pts[outside_before])
    assert not inside_many(out, *GEOM.args()).any()
    # A reflection never lengthens the step beyond its original length (plus the 1 mm push).
    step0 = np.linalg.norm(pts - prev, axis=1)
    step1 = np.linalg.norm(out - prev, axis=1)
    assert np.all(step1 <= step0 + 2e-3)


def test_voxelize_counts_cells() -> None:
    geom = BuildingArrays.from_buildings((BoxBuilding(4.0, 6.0, 10.0, 6.0, 8.0, anchor="corner"),))
    cells = voxelize(0.0, 0.0, 1.0, 1.0, 1.0, 20, 20, 12, *geom.args())
    assert int((cells == 0).sum()) == 10 * 6 * 8
    assert (cells[4:14, 6:12, :8] == 0).all()
    assert (cells[:, :, 8:] == -1).all()
