"""Urban scene configuration: named errors, footprints, layouts (SI units, NED, heights up)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.world.urban import (
    PAPER_S4_START_NED,
    BoxBuilding,
    ConfigError,
    GridSpec,
    LogWindProfile,
    PolygonBuilding,
    UrbanOptions,
    UrbanScene,
    paper_s4_scene,
    parse_urban_scene,
)


def _table(**over: object) -> dict:
    table: dict = {
        "wind": {"speed_m_s": 7.0, "from_deg": 45.0},
        "grid": {"x_min_m": 0, "y_min_m": 0, "length_x_m": 100, "length_y_m": 100, "height_m": 40, "spacing_m": 2},
        "buildings": [
            {"type": "box", "x_m": 30, "y_m": 30, "length_m": 10, "width_m": 10, "height_m": 8},
            {"type": "box", "x_m": 60, "y_m": 30, "length_m": 10, "width_m": 10, "height_m": 8},
            {"type": "polygon", "vertices_m": [[40, 60], [50, 60], [50, 70]], "height_m": 12},
        ],
    }
    table.update(over)
    return table


def test_parse_builds_the_scene() -> None:
    scene = parse_urban_scene(_table())
    assert len(scene.buildings) == 3
    assert isinstance(scene.buildings[2], PolygonBuilding)
    assert scene.grid.shape == (50, 50, 20)


def test_building_error_names_index_and_field() -> None:
    table = _table()
    table["buildings"][2]["height_m"] = -3
    with pytest.raises(ConfigError) as err:
        parse_urban_scene(table)
    assert str(err.value) == "buildings[2].height_m = -3: must be > 0 (m)"
    assert err.value.path == "buildings[2].height_m"


@pytest.mark.parametrize(
    ("patch", "path"),
    [
        (lambda t: t["buildings"][0].update(width_m="wide"), "buildings[0].width_m"),
        (lambda t: t["buildings"][1].update(colour="red"), "buildings[1].colour"),
        (lambda t: t["buildings"][1].update(type="dome"), "buildings[1].type"),
        (lambda t: t["buildings"][0].update(anchor="middle"), "buildings[0].anchor"),
        (lambda t: t["buildings"][2].update(vertices_m=[[0, 0], [9, 9], [9, 0], [0, 9]]), "buildings[2].vertices_m"),
        (lambda t: t["buildings"][0].pop("height_m"), "buildings[0].height_m"),
        (lambda t: t["wind"].update(reference_height_m=0.05), "wind.reference_height_m"),
        (lambda t: t["wind"].update(from_deg=float("nan")), "wind.from_deg"),
        (lambda t: t["grid"].update(length_x_m=101), "grid.length_x_m"),
        (lambda t: t["grid"].update(spacing_m=0), "grid.spacing_m"),
        (lambda t: t.update(options={"solver_tol": 0.5}), "options.solver_tol"),
        (lambda t: t.update(options={"amg": "jacobi"}), "options.amg"),
        (lambda t: t.update(options={"rooftop": "yes"}), "options.rooftop"),
        (lambda t: t.update(extra=1), "extra"),
    ],
)
def test_bad_values_are_named(patch, path: str) -> None:
    table = _table()
    patch(table)
    with pytest.raises(ConfigError) as err:
        parse_urban_scene(table)
    assert err.value.path == path, str(err.value)
    assert str(err.value).startswith(path)
    assert "\n" not in str(err.value)


def test_building_outside_grid_or_too_tall() -> None:
    table = _table()
    table["buildings"][0]["x_m"] = 99
    with pytest.raises(ConfigError, match=r"^buildings\[0\] = .*must lie inside the grid"):
        parse_urban_scene(table)
    table = _table()
    table["buildings"][1]["height_m"] = 39
    with pytest.raises(ConfigError, match=r"^buildings\[1\]\.height_m = 39.0: must be at least one cell below"):
        parse_urban_scene(table)


def test_box_footprint_center_corner_and_rotation() -> None:
    box = BoxBuilding(10.0, 20.0, 8.0, 4.0, 5.0)
    fp = box.footprint()
    assert fp.min(axis=0) == pytest.approx([6.0, 18.0])
    assert fp.max(axis=0) == pytest.approx([14.0, 22.0])
    corner = BoxBuilding(10.0, 20.0, 8.0, 4.0, 5.0, anchor="corner").footprint()
    assert corner.min(axis=0) == pytest.approx([10.0, 20.0])
    # Rotated 90 deg (clockwise from north toward east): the length now runs east.
    rot = BoxBuilding(0.0, 0.0, 8.0, 4.0, 5.0, rotation_deg=90.0).footprint()
    assert np.ptp(rot[:, 1]) == pytest.approx(8.0)
    assert np.ptp(rot[:, 0]) == pytest.approx(4.0)
    # Counter-clockwise in the (x, y) plane: positive signed area.
    for f in (fp, corner, rot, BoxBuilding(0, 0, 3, 2, 1, rotation_deg=-33).footprint()):
        area = 0.5 * np.sum(f[:, 0] * np.roll(f[:, 1], -1) - np.roll(f[:, 0], -1) * f[:, 1])
        assert area > 0


def test_polygon_is_reordered_counter_clockwise() -> None:
    cw = PolygonBuilding(((0.0, 0.0), (0.0, 10.0), (10.0, 10.0), (10.0, 0.0)), 5.0)
    f = cw.footprint()
    assert 0.5 * np.sum(f[:, 0] * np.roll(f[:, 1], -1) - np.roll(f[:, 0], -1) * f[:, 1]) == pytest.approx(100.0)


def test_wind_direction_and_profile() -> None:
    w = LogWindProfile(7.0, 45.0, 10.0, 0.1)
    assert w.direction_ned == pytest.approx((-math.sqrt(0.5), -math.sqrt(0.5)))  # toward the south-west
    assert float(w.speed_at(10.0)) == pytest.approx(7.0)
    assert float(w.speed_at(0.05)) == 0.0
    assert w.friction_velocity_m_s == pytest.approx(0.4 * 7.0 / math.log(100.0))


def test_paper_layout_is_valid_and_start_is_free() -> None:
    scene = paper_s4_scene()
    assert len(scene.buildings) == 6
    assert scene.grid.shape == (200, 200, 30)
    assert scene.wind.from_deg == 45.0 and scene.wind.speed_m_s == 7.0
    start = np.array(PAPER_S4_START_NED)
    for b in scene.buildings:  # the start is in the open, well away from every block
        fp = b.footprint()
        assert np.any(start < fp.min(axis=0) - 50.0) or np.any(start > fp.max(axis=0) + 50.0)
    assert max(b.height_m for b in scene.buildings) * 3 <= scene.grid.height_m


def test_scene_rejects_wrong_types() -> None:
    grid = GridSpec(0, 0, 40, 40, 20, 2)
    with pytest.raises(ConfigError, match=r"^buildings\[0\]"):
        UrbanScene(("not a building",), LogWindProfile(), grid)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"^options"):
        UrbanScene((), LogWindProfile(), grid, options={"rooftop": False})  # type: ignore[arg-type]
    assert UrbanScene((), LogWindProfile(), grid, UrbanOptions(rooftop=False)).options.rooftop is False
