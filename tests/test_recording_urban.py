"""Urban layers of a recording (issue 20 item 6), read back from real ``.rrd`` files.

A short in-process paper-s4 trial (a few seconds of flight) is recorded; its file must carry the
scenario's buildings (boxes with their sizes, positions and headings; footprints on the map), the
mean wind field at the search altitude on the map and on the vertical section in 3D with the
field's own values (compared with :meth:`UrbanWindField.mean` at the drawn points), a map extent
holding the buildings, and the views that show them. An open-field recording gains none of it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mission.runners.inprocess import run_trial
from mission.strategies.params import load_params
from recording.read import RrdLog
from recording.recorder import RunRecorder
from recording.style import speed_colormap
from recording.trial import TrialRecorder
from recording.urban_scene import rectangle
from sitl.scenario import load_scenario
from sitl.world.urban.cache import load_or_solve

SEED = 101  # a development seed
URBAN_PREFIXES = ("map/buildings", "world/buildings", "map/wind_field", "world/wind_field")


@pytest.fixture(scope="module")
def urban(tmp_path_factory: pytest.TempPathFactory) -> tuple[RrdLog, object, object]:
    path = tmp_path_factory.mktemp("urban") / "s4.rrd"
    recorded = run_trial("paper-s4", "surge-cast", seed=SEED, time_limit_s=4.0, keep_track=True,
                         recorder=TrialRecorder(path))  # fmt: skip
    plain = run_trial("paper-s4", "surge-cast", seed=SEED, time_limit_s=4.0, keep_track=True)
    assert recorded.track == plain.track and recorded.path_m == plain.path_m  # the layers only read the world
    sc = load_scenario("paper-s4")
    assert sc.urban is not None
    return RrdLog(path), sc, load_or_solve(sc.urban)


def _image(log: RrdLog, entity: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RGBA (H, W, 4) of a static image and its Transform3D translation and scale (map units)."""
    _, imgs = log.images(entity)  # a PNG (recording.png) or raw
    img = imgs[-1]
    _, tr = log.column(entity, "Transform3D:translation")
    _, sc = log.column(entity, "Transform3D:scale")
    return img, np.asarray(tr[-1][0], dtype=float), np.asarray(sc[-1][0], dtype=float)


def _rgba32(packed: list[int]) -> np.ndarray:
    """Rerun's packed 0xRRGGBBAA colours -> (N, 4) uint8."""
    p = np.asarray(packed, dtype=np.uint64)
    return np.stack([(p >> s) & 0xFF for s in (24, 16, 8, 0)], axis=1).astype(np.uint8)


def _vmax(log: RrdLog) -> float:
    """The speed colour bar's top label [m/s] (the colour scale's high end)."""
    _, labels = log.column("map/wind_field/colorbar/labels", "Points2D:labels")
    return max(float(x) for x in labels[-1])


def test_buildings_are_the_scenarios(urban: tuple[RrdLog, object, object]) -> None:
    log, sc, _ = urban
    bs = sc.urban.buildings  # type: ignore[attr-defined]
    _, centers = log.column("world/buildings", "Boxes3D:centers")
    _, half = log.column("world/buildings", "Boxes3D:half_sizes")
    _, rot = log.column("world/buildings", "Boxes3D:rotation_axis_angles")
    _, fill = log.column("world/buildings", "Boxes3D:fill_mode")
    _, colors = log.column("world/buildings", "Boxes3D:colors")
    _, labels = log.column("world/buildings", "Boxes3D:labels")
    assert len(centers[-1]) == len(bs) == 6
    assert labels[-1] == [b.name for b in bs]
    for c, h, r, b in zip(centers[-1], half[-1], rot[-1], bs, strict=True):
        assert b.anchor == "center"
        np.testing.assert_allclose(c, [b.x_m, b.y_m, -0.5 * b.height_m], atol=1e-3)
        np.testing.assert_allclose(h, [0.5 * b.length_m, 0.5 * b.width_m, 0.5 * b.height_m], atol=1e-3)
        assert r["axis"] == [0.0, 0.0, 1.0] and r["angle"] == pytest.approx(math.radians(b.rotation_deg), abs=1e-6)
    assert fill[-1] == [3]  # FillMode.Solid (1 major wireframe, 2 dense wireframe)
    assert 0 < _rgba32(colors[-1])[0, 3] < 160  # translucent: the path behind stays visible
    _, outline = log.column("world/buildings/outline", "Boxes3D:fill_mode")
    assert outline[-1] == [1]
    # The map: each footprint's closed outline, the fill image opaque inside a block and clear between them.
    _, strips = log.column("map/buildings/outline", "LineStrips2D:strips")
    for strip, b in zip(strips[-1], bs, strict=True):
        fp = b.footprint()
        ring = fp[[0, 1, 2, 3, 0]]
        np.testing.assert_allclose(np.asarray(strip), np.column_stack([ring[:, 1], -ring[:, 0]]), atol=1e-3)
    img, tr, scale = _image(log, "map/buildings/fill")

    def alpha_at(n: float, e: float) -> int:
        return int(img[int((-n - tr[1]) / scale[1]), int((e - tr[0]) / scale[0]), 3])

    assert all(alpha_at(b.x_m, b.y_m) > 100 for b in bs)
    assert alpha_at(385.95, 76.0) == 0  # the cross street between block-2 and block-5


def test_map_opens_on_the_search_and_the_buildings(urban: tuple[RrdLog, object, object]) -> None:
    log, sc, _ = urban
    lay = log.layout()
    assert lay is not None and lay.bounds_ne is not None
    n0, n1, e0, e1 = lay.bounds_ne
    for b in sc.urban.buildings:  # type: ignore[attr-defined]
        fp = b.footprint()
        assert n0 <= fp[:, 0].min() and fp[:, 0].max() <= n1 and e0 <= fp[:, 1].min() and fp[:, 1].max() <= e1
    assert n1 - n0 < 200.0 and e1 - e0 < 250.0  # the search area, not the grid or the puffs' drift
    views = {(cls, origin) for cls, origin, _ in log.blueprint_views()}
    assert {("2D", "map"), ("3D", "world")} <= views
    contents = log.blueprint_view_contents()
    for origin in ("map", "world"):  # everything under the origin: the urban layers included
        assert contents[origin] == ["$origin/**"], contents[origin]
    paths = log.entity_paths()
    for e in ("map/buildings/fill", "map/buildings/outline", "map/buildings/label", "world/buildings",
              "map/wind_field/speed", "map/wind_field/arrows", "map/wind_field/colorbar/image",
              "world/wind_field/section", "world/wind_field/section/arrows"):  # fmt: skip
        assert e in paths
        assert e not in log.temporal_entity_paths()  # static: logged once


def test_wind_slice_is_the_fields(urban: tuple[RrdLog, object, object]) -> None:
    log, sc, field = urban
    alt = load_params("surge-cast").altitude_m  # the search altitude
    vmax = _vmax(log)
    img, tr, scale = _image(log, "map/wind_field/speed")
    rng = np.random.default_rng(7)
    bs = sc.urban.buildings  # type: ignore[attr-defined]
    # Random pixels and the pixels at the buildings' centres.
    rows = np.concatenate([rng.integers(0, img.shape[0], 40), [int((-b.x_m - tr[1]) / scale[1]) for b in bs]])
    cols = np.concatenate([rng.integers(0, img.shape[1], 40), [int((b.y_m - tr[0]) / scale[0]) for b in bs]])
    e = tr[0] + (cols + 0.5) * scale[0]
    n = -(tr[1] + (rows + 0.5) * scale[1])
    pts = np.column_stack([n, e, np.full(len(n), -alt)])
    w = field.mean(pts)  # type: ignore[attr-defined]
    inside = field.inside(pts)  # type: ignore[attr-defined]
    got = img[rows, cols]
    assert inside.any() and (~inside).sum() > 20
    np.testing.assert_array_equal(got[inside, 3], 0)  # buildings: no wind drawn
    want = speed_colormap(np.hypot(w[~inside, 0], w[~inside, 1]), vmax)
    assert np.abs(got[~inside, :3].astype(int) - want.astype(int)).max() <= 1
    # Arrows: centred on their sample points, along the field there, one length scale for all.
    _, origins = log.column("map/wind_field/arrows", "Arrows2D:origins")
    _, vectors = log.column("map/wind_field/arrows", "Arrows2D:vectors")
    o, v = np.asarray(origins[-1]), np.asarray(vectors[-1])
    mid = o + 0.5 * v
    w = field.mean(np.column_stack([-mid[:, 1], mid[:, 0], np.full(len(mid), -alt)]))  # type: ignore[attr-defined]
    w_map = np.column_stack([w[:, 1], -w[:, 0]])
    k = np.hypot(*v.T) / np.hypot(*w_map.T)
    assert len(v) > 50 and np.allclose(k, k[0], rtol=1e-3)
    np.testing.assert_allclose(v, k[0] * w_map, atol=1e-3)


def test_vertical_section_is_the_fields(urban: tuple[RrdLog, object, object]) -> None:
    log, sc, field = urban
    _, pos = log.column("world/wind_field/section", "Mesh3D:vertex_positions")
    _, col = log.column("world/wind_field/section", "Mesh3D:vertex_colors")
    p, c = np.asarray(pos[-1], dtype=float), _rgba32(col[-1])
    src = np.asarray(sc.plume.plume.sources[0].position_ned, dtype=float)  # type: ignore[attr-defined]
    w_src = field.mean(src)  # type: ignore[attr-defined]
    u = w_src[:2] / np.hypot(*w_src[:2])
    off = p[:, :2] - src[:2]
    np.testing.assert_allclose(off[:, 0] * u[1] - off[:, 1] * u[0], 0.0, atol=1e-3)  # in the plane along the wind
    assert p[:, 2].min() < -20.0 and p[:, 2].max() == 0.0  # from the ground to above the 20 m roofs
    sel = np.random.default_rng(3).choice(len(p), 60, replace=False)
    w = field.mean(p[sel])  # type: ignore[attr-defined]
    out = ~field.inside(p[sel])  # type: ignore[attr-defined]
    speed = np.hypot(w[out, :2] @ u, w[out, 2])  # in-plane speed
    want = speed_colormap(speed, _vmax(log))
    assert np.abs(c[sel][out, :3].astype(int) - want.astype(int)).max() <= 1


def test_open_field_recording_has_no_urban_layers(tmp_path: Path) -> None:
    path = tmp_path / "open.rrd"
    run_trial("open-field", "surge-cast", seed=SEED, time_limit_s=2.0, recorder=TrialRecorder(path))
    paths = RrdLog(path).entity_paths()
    assert "map/plume" in paths or "map/path" in paths  # it did record
    assert not [p for p in paths if p.startswith(URBAN_PREFIXES)]


def test_a_polygon_building_is_drawn_as_walls(tmp_path: Path) -> None:
    """A non-rectangular footprint (an L) gets walls and a roof outline in 3D, a footprint on the map."""
    ell = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 8.0], [8.0, 8.0], [8.0, 20.0], [0.0, 20.0]])
    box = np.array([[40.0, 0.0], [50.0, 0.0], [50.0, 10.0], [40.0, 10.0]])
    assert rectangle(ell) is None and rectangle(box) is not None
    with RunRecorder(tmp_path / "poly.rrd") as rec:
        rec.buildings([ell, box], [12.0, 6.0], ["ell", "box"])
    log = RrdLog(tmp_path / "poly.rrd")
    _, pos = log.column("world/buildings/walls", "Mesh3D:vertex_positions")
    walls = np.asarray(pos[-1])
    assert len(walls) == 4 * len(ell) and walls[:, 2].min() == pytest.approx(-12.0)
    _, centers = log.column("world/buildings", "Boxes3D:centers")
    np.testing.assert_allclose(centers[-1], [[45.0, 5.0, -3.0]])
    _, labels = log.column("map/buildings/label", "Points2D:labels")
    assert labels[-1] == ["ell 12 m", "box 6 m"]
