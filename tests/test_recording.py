"""The Rerun recorder: real .rrd files written and read back with ``rerun.chunk.RrdReader``.

One 15 s open-field simulation is recorded through ``record_simulation`` (module fixture) and
checked against the simulation itself; the recorder's methods are checked with known values; the
layout (blueprint) is read back from the file: its views, the time range its plots open on and
the value ranges fitted to the data.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from recording.layout import LEGEND_PAD
from recording.read import RrdLog
from recording.recorder import BAND_DT, MARKER_SPAN, RunRecorder
from recording.sim_hook import record_simulation, wind_speed_from_deg
from recording.style import TIMELINE, conc_image, log_colormap, posterior_image
from sitl.scenario import load_scenario
from sitl.simulation import Simulation

DURATION_S = 15.0


@pytest.fixture(scope="module")
def sim_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Simulation, RrdLog]:
    path = tmp_path_factory.mktemp("rrd") / "open-field.rrd"
    sim = Simulation(load_scenario("open-field").with_duration(DURATION_S))
    with RunRecorder(path, scenario="open-field", strategy="none", seed=sim.seed) as rec:
        record_simulation(sim, rec)
        sim.run(DURATION_S)
    return sim, RrdLog(path)


def test_sim_recording_has_expected_entities_on_one_timeline(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    temporal = set(log.temporal_entity_paths()) | set(log.series())  # rotors/1 and chem/value share rows
    expected = {
        "world/vehicle", "world/trail", "world/wind/truth", "world/plume/curtain",
        "map/vehicle", "map/path", "map/plume", "map/wind/truth", "phases/mission", "phases/mode",
        "wind/north/truth", "wind/east/truth", "wind/down/truth", "wind/speed/truth", "wind/direction/truth",
        "rotors/1", "rotors/2", "rotors/3", "rotors/4", "chem/value", "chem/log10", "chem/threshold_log10",
        "log/events",
    }  # fmt: skip
    assert expected <= temporal, expected - temporal
    static = set(log.entity_paths())
    assert {"world", "world/vehicle/body", "world/sources/true", "map/sources/true", "map/north", "map/scale",
            "summary"} <= static  # fmt: skip
    assert "wind/north/estimate" not in temporal  # no estimator ran: a style, no data
    assert "world/plume/puffs" not in temporal  # off by default: the concentration field shows the plume
    assert log.timelines() == {TIMELINE}  # one clock; wall-clock log_time is off
    assert log.application_ids == ["windseek"]


def test_vehicle_pose_and_path(sim_run: tuple[Simulation, RrdLog]) -> None:
    sim, log = sim_run
    t, pos = log.vectors("world/vehicle", "Transform3D:translation")
    assert len(t) == 375  # 25 Hz from t = 0 over 15 s
    np.testing.assert_allclose(np.diff(t), 0.04, atol=1e-9)
    assert pos[0, 2] == pytest.approx(0.0, abs=0.05)
    assert -pos[-1, 2] == pytest.approx(5.0, abs=0.3)
    np.testing.assert_allclose(pos[-1], sim.position, atol=0.05)
    _, quat = log.column("world/vehicle", "Transform3D:quaternion")
    np.testing.assert_allclose(np.linalg.norm(np.array([np.ravel(v) for v in quat]), axis=1), 1.0, atol=1e-5)
    _, strips = log.column("world/trail", "LineStrips3D:strips")
    path = np.vstack([np.array(row[0]) for row in strips])  # one segment per row
    assert path.shape[1] == 3 and -path[:, 2].max() < 0.5 and -path[:, 2].min() > 4.0  # ground to altitude
    # The map is north up: map (x, y) = (east, -north), the same path.
    t_m, m = log.vectors("map/vehicle", "Points2D:positions")
    np.testing.assert_array_equal(t_m, t)
    np.testing.assert_allclose(m, np.column_stack([pos[:, 1], -pos[:, 0]]), atol=1e-5)


def test_rotor_speeds_and_wind_truth(sim_run: tuple[Simulation, RrdLog]) -> None:
    sim, log = sim_run
    t_pos, pos = log.vectors("world/vehicle", "Transform3D:translation")
    flying = -pos[:, 2] > 1.0
    t, w = log.scalars("rotors/1")
    np.testing.assert_array_equal(t, t_pos)
    assert w[flying].mean() == pytest.approx(393.0, abs=30.0)  # hover
    t, n = log.scalars("wind/north/truth")
    _, e = log.scalars("wind/east/truth")
    _, d = log.scalars("wind/down/truth")
    # The wind the physics used at its IMU instants (at most one IMU period before each pose row),
    # at their own times: the field again there, at the position interpolated from the poses.
    imu_dt = 1.0 / sim.scenario.sensors.imu.rate_hz
    assert np.all((t_pos - t >= -1e-9) & (t_pos - t <= imu_dt + 1e-9))
    at = np.column_stack([np.interp(t, t_pos, pos[:, k]) for k in range(3)])
    again = np.array([sim.wind.velocity(ti, p) for ti, p in zip(t, at, strict=True)])
    np.testing.assert_allclose(np.column_stack([n, e, d]), again, atol=2e-3)
    _, s = log.scalars("wind/speed/truth")
    np.testing.assert_allclose(s, np.hypot(n, e), rtol=1e-6)
    # From-direction unwrapped about the first value: wind from about north -> near 0, no 360 jumps.
    _, from_deg = log.scalars("wind/direction/truth")
    assert np.abs(np.diff(from_deg)).max() < 90.0 and np.abs(from_deg).max() < 60.0
    ref = from_deg[0]
    wrapped = np.array([wind_speed_from_deg(np.array([a, b, 0.0]))[1] for a, b in zip(n, e, strict=True)])
    np.testing.assert_allclose((from_deg - wrapped + 180.0) % 360.0 - 180.0, 0.0, atol=1e-3)
    assert abs(from_deg - ref).max() <= 180.0


def test_chem_readings_on_a_log_scale(sim_run: tuple[Simulation, RrdLog]) -> None:
    sim, log = sim_run
    t, c = log.scalars("chem/value")
    model = sim.chem
    assert len(c) == model.n_samples == 150  # every 10 Hz reading, none dropped or doubled
    assert c.max() == pytest.approx(model.peak_mg_m3, rel=1e-9)
    t_l, lg = log.scalars("chem/log10")
    np.testing.assert_array_equal(t_l, t)
    np.testing.assert_allclose(lg, np.log10(np.maximum(c, 1e-2)), rtol=1e-6)
    t_th, th = log.scalars("chem/threshold_log10")
    np.testing.assert_allclose(th, math.log10(0.05))  # the sensor's detection limit, drawn across the run
    assert t_th[0] == 0.0 and t_th[-1] == pytest.approx(DURATION_S, abs=0.1)
    # Every reading at or above the threshold is a hit on the map, at the vehicle (one row each).
    t_h, _ = log.column("map/hits", "Points2D:positions")
    assert len(t_h) == int((c >= 0.05).sum()) > 0
    np.testing.assert_allclose(t_h, t[c >= 0.05])


def test_plume_slice_image_and_curtain(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    t, fmt = log.column("map/plume", "Image:format")
    assert len(t) == 8  # 0.5 Hz over 15 s
    assert fmt[-1][0]["width"] == 31 and fmt[-1][0]["height"] == 61  # 2 m cells, north up
    # The grid's north-west corner, NED (n, e) = (90 + 1, -30 - 1) m, is map (x, y) = (e, -n); 2 m per pixel.
    _, tr = log.vectors("map/plume", "Transform3D:translation")
    np.testing.assert_allclose(tr[-1], [-31.0, -91.0, 0.0])
    _, buf = log.column("map/plume", "Image:buffer")
    alpha = np.frombuffer(bytes(buf[-1][0]), dtype=np.uint8).reshape(61, 31, 4)[..., 3].astype(float)
    assert (alpha > 0).sum() > 10  # the plume, transparent around it
    east = -30.0 + 2.0 * np.arange(31)
    assert abs((alpha.sum(axis=0) * east).sum() / alpha.sum()) < 10.0  # along the north-south axis of the wind
    _, opacity = log.column("map/plume", "Image:opacity")
    assert opacity[-1][0] < 1.0  # below 1 the viewer blends by the alpha channel (transparent edge)
    _, curtain = log.column("world/plume/curtain", "Points3D:positions")
    c = np.array(curtain[-1])
    assert np.abs(c[:, 1]).max() < 5.0 and c[:, 2].min() < -3.0  # the plane along the wind, above ground


def test_phases_and_events(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    assert [s for _, s in log.states("phases/mission")][:1] == ["armed"]
    assert "AUTO.MISSION" in [s for _, s in log.states("phases/mode")]
    bodies = [b for _, b in log.texts("log/events")]
    assert "armed" in bodies and "flight mode AUTO.MISSION" in bodies


def test_blueprint_layout_and_ranges(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    assert log.blueprint_count == 2  # a usable layout from the start, the final one at close
    views = {(cls, origin) for cls, origin, _ in log.blueprint_views()}
    assert ("2D", "map") in views and ("3D", "world") in views
    assert ("StateTimeline", "phases") in views and ("TextDocument", "summary") in views
    assert ("TextLog", "log") in views
    for origin in ("wind/north", "wind/east", "wind/down", "wind/speed", "wind/direction", "chem", "rotors",
                   "flight/altitude"):
        assert ("TimeSeries", origin) in views, origin
    # Every plot opens on the whole run, with room on the right for the legends.
    ranges = log.blueprint_time_ranges()
    assert len(ranges) == 9  # 8 plots (the altitude's too; no velocity, attitude, battery, GPS) and the phase lanes
    for t0, t1 in ranges:
        assert t0 == pytest.approx(0.0) and t1 == pytest.approx(14.98 + LEGEND_PAD * 14.98, abs=0.05)
    assert 0.25 <= LEGEND_PAD <= 0.4  # a legend (~180 px) clear of the data in a plot half a 1600 px window wide
    lay = log.layout()
    assert lay is not None and lay.t_range == pytest.approx((0.0, 14.96), abs=0.03)
    # Value axes fitted to the data: the rotor plot to the flight, not to the rotors at rest.
    lo, hi = lay.y_ranges["rotors"]
    assert 300.0 < lo < 393.0 < hi < 500.0
    # The map frames the search area (start and source with a margin), not the plume's extent.
    n0, n1, e0, e1 = lay.bounds_ne
    assert -20.0 < n0 < 0.0 and 60.0 < n1 < 80.0 and (e1 - e0) <= 1.5 * (n1 - n0)
    # With chemical readings the map shows the concentration colour bar (everything under map/).
    assert log.blueprint_view_contents()["map"] == ["$origin/**"]


def test_colormaps_are_light_at_the_low_end() -> None:
    rgb = log_colormap(np.array([0.0, 1e-2, 1.0, 100.0, 1e4]), 1e-2, 1e2)
    assert (rgb[0] == rgb[1]).all() and (rgb[-1] == rgb[-2]).all()  # clipped
    assert rgb[1].astype(int).sum() > 600 and rgb[3].astype(int).sum() < 250  # light yellow .. dark red
    img = conc_image(np.array([[0.0, 0.05], [1.0, 100.0]]), 1e-2, 1e2)  # rows: north 0, north 1
    assert img.shape == (2, 2, 4)
    assert img[1, 0, 3] == 0  # no plume: transparent (row 1 = the southern row)
    assert 0 < img[1, 1, 3] < img[0, 0, 3] < img[0, 1, 3]  # opacity rises with concentration
    p = posterior_image(np.array([[0.0, 0.25], [1.0, 0.0]]))  # grid rows: north 0, north 1
    assert p[0, 1, 3] == p[1, 0, 3] == 0 and 0 < p[1, 1, 3] < p[0, 0, 3]  # image row 0 = the northern row


def test_recorder_methods_with_known_values(tmp_path: Path) -> None:
    path_a, path_b = tmp_path / "a.rrd", tmp_path / "b.rrd"
    with RunRecorder(path_a, strategy="zigzag", series_flush_s=0.3) as a, RunRecorder(path_b, blueprint=False) as b:
        for k in range(20):
            t = 0.1 * k
            a.vehicle(t, [0.5 * k, 0.0, -5.0], [1.0, 0.0, 0.0, 0.0])
            a.wind(t, truth_ned=[-5.0, 0.0, 0.0], est_ned=[-4.0, 1.0, 0.5], sigma_ned=[0.5, 0.25, 0.1])
            a.wind_speed_dir(t, 5.0, 350.0 + k if k else math.nan, dir_filt_deg=370.0)
            a.chem(t, 0.2 * k, 1.0)
            b.rotors(t, [400.0 + k, 401.0, 402.0, 403.0])
        a.sources([[10.0, 0.0, -1.0]], declared_ned=[9.0, 1.0, -1.0], confidence=0.9)
        a.geofence([-20.0, -20.0, -30.0], [20.0, 20.0, 0.0])
        a.text(1.0, "surge", "warn", channel="strategy")
        a.autopilot_event(1.2, "[commander] \x1b[32mReady for takeoff!\x1b[0m\t")
        a.mission_statustext(1.5, "holding", who="245:190")
        with pytest.raises(ValueError, match="level"):
            a.text(1.0, "x", "LOUD")
    la, lb = RrdLog(path_a), RrdLog(path_b)
    # The band is one series crossing it at every sample (Rerun 0.41 cannot fill between two lines): two
    # rows per sample, BAND_DT apart, up at one sample and down at the next.
    t2, zig = la.scalars("wind/north/band")
    assert zig.shape == (40,) and np.all(np.diff(t2) > 0.0)
    np.testing.assert_allclose(np.diff(t2)[0::2], BAND_DT, atol=2e-9)
    np.testing.assert_allclose(zig[:4], [-5.0, -3.0, -3.0, -5.0])  # -4 -+ 2 * 0.5: up, then down
    t, lo, hi = la.band("wind/north/band")
    assert len(t) == 20 and t[-1] == pytest.approx(1.9)
    np.testing.assert_allclose(lo, -5.0)
    np.testing.assert_allclose(hi, -3.0)
    _, lo, hi = la.band("wind/east/band")
    np.testing.assert_allclose(np.column_stack([lo, hi]), [[0.5, 1.5]] * 20)
    _, raw = la.scalars("wind/direction/raw")
    assert len(raw) == 19  # the NaN sample is a gap, not a point
    # Unwrapped about the first value (the filtered 370 = 10 deg): 351 .. 9 deg as -9 .. 9, no jump at 0.
    np.testing.assert_allclose(raw, np.arange(-9.0, 10.0))
    np.testing.assert_allclose(la.scalars("wind/direction/filtered")[1], 10.0)
    np.testing.assert_allclose(la.scalars("chem/value")[1], 0.2 * np.arange(20))
    _, hits = la.column("map/hits", "Points2D:positions")
    assert len(hits) == 15  # readings 1.0 .. 3.8 mg/m^3 at or above the threshold, at the vehicle
    np.testing.assert_allclose([h[0] for h in hits], [[0.0, -0.5 * k] for k in range(5, 20)])
    _, colors = la.column("map/hits", "Points2D:colors")
    assert len({tuple(c) for c in colors}) > 1  # coloured by concentration
    # each hit's own concentration on the colour scale (mapped per sent batch: RGBA packed 0xRRGGBBAA)
    rgb = log_colormap(0.2 * np.arange(5, 20), *a.c_range_mg_m3)
    want = [(int(r) << 24) | (int(g) << 16) | (int(b) << 8) | 0xFF for r, g, b in rgb]
    assert [int(np.ravel(c)[0]) for c in colors] == want
    t_dec, lab = la.column("map/sources/declared/label", "Points2D:labels")
    assert lab == [["declared 90%"]] and t_dec[0] == pytest.approx(1.9)  # at the latest time logged
    # In 3D the labels sit on their own points, the true source's above it, the declared one's below:
    # a declaration a few metres off no longer hides one label under the other.
    _, true_lab = la.vectors("world/sources/true/label", "Points3D:positions")
    _, dec_lab = la.vectors("world/sources/declared/label", "Points3D:positions")
    np.testing.assert_allclose(true_lab[-1], [10.0, 0.0, -5.0])
    np.testing.assert_allclose(dec_lab[-1], [9.0, 1.0, 3.0])
    assert la.column("world/sources/declared/label", "Points3D:labels")[1] == [["declared 90%"]]
    assert la.column("world/sources/true/label", "Points3D:labels")[1] == [["source"]]
    assert la.texts("log/strategy") == [(pytest.approx(1.0), "surge")]
    # Events read as sentences: PX4's terminal colours, tabs and an unknown sender's MAVLink ids.
    assert la.texts("log/events")[-1][1] == "[commander] Ready for takeoff!"
    assert la.texts("log/wire") == [(pytest.approx(1.5), "system 245 component 190: holding")]
    _, lvl = la.column("log/strategy", "TextLog:level")
    assert lvl == [["WARN"]]
    assert "map/geofence" in la.entity_paths() and "world/geofence" in la.entity_paths()
    np.testing.assert_allclose(lb.scalars("rotors/1")[1], 400.0 + np.arange(20))
    assert lb.blueprint_count == 0 and la.blueprint_count == 2
    # What had no data says so: the layout shows a text instead of an empty plot.
    assert "no rotor speeds" in (la.document("missing/rotors") or "")
    assert ("TextDocument", "missing/rotors") in {(c, o) for c, o, _ in la.blueprint_views()}
    assert "rotors" not in {o for c, o, _ in la.blueprint_views() if c == "TimeSeries"}
    # b had no chemical readings: its map leaves out the concentration colour bar (it would suggest a plume).
    assert "map/colorbar/image" in lb.entity_paths() and lb.blueprint_count == 0
    with RunRecorder(tmp_path / "c.rrd") as c:
        c.vehicle(0.0, [0.0, 0.0, -5.0], [1.0, 0.0, 0.0, 0.0])
    assert RrdLog(tmp_path / "c.rrd").blueprint_view_contents()["map"] == ["$origin/**", "- $origin/colorbar/**"]
    assert la.blueprint_view_contents()["map"] == ["$origin/**"]
    # The colour bar's labels sit left of the bar (not over its colours), its unit under it.
    _, bar = la.vectors("map/colorbar/image", "Transform3D:translation")
    _, labels = la.column("map/colorbar/labels", "Points2D:positions")
    _, names = la.column("map/colorbar/labels", "Points2D:labels")
    assert names[-1] == ["100", "10", "1", "0.1", "0.01"] and all(x < bar[-1][0] for x, _ in labels[-1])
    assert la.column("map/colorbar/unit", "Points2D:labels")[1][-1] == ["mg/m³"]


def test_path_segments_join_and_carry_the_state_colour(tmp_path: Path) -> None:
    path = tmp_path / "path.rrd"
    with RunRecorder(path, strategy="surge-cast") as rec:
        for k in range(50):
            if k == 20:  # before: on the ground, the path is grey
                rec.armed(2.0, True)
                rec.flight_mode(2.0, "OFFBOARD")
                rec.strategy_state(2.0, "surge")
            rec.vehicle(0.1 * k, [float(k), 0.0, -5.0], [1.0, 0.0, 0.0, 0.0])
    log = RrdLog(path)
    t, strips = log.column("map/path", "LineStrips2D:strips")
    segs = np.array([row[0] for row in strips])  # (N, 2 points, map x/y)
    assert len(segs) == 49 and (np.diff(t) > 0).all()
    np.testing.assert_allclose(segs[1:, 0], segs[:-1, 1])  # each segment starts where the last ended
    np.testing.assert_allclose(segs[0, 0], [0.0, 0.0]) and np.testing.assert_allclose(segs[-1, 1], [0.0, -49.0])
    _, colors = log.column("map/path", "LineStrips2D:colors")
    from recording.style import state_color

    def rgb(c: int) -> tuple[int, int, int]:  # rerun packs colours as 0xRRGGBBAA
        return (c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255

    assert rgb(colors[0][0]) == state_color("ground") and rgb(colors[-1][0]) == state_color("surge")
    lay = log.layout()
    assert lay is not None and lay.bounds_ne[1] > 49.0  # the map's extent covers the path


def test_marker_lines_are_vertical_and_separated(tmp_path: Path) -> None:
    path = tmp_path / "m.rrd"
    with RunRecorder(path, strategy="surge-cast") as rec:
        for k in range(200):
            t = 0.1 * k
            rec.vehicle(t, [0.1 * k, 0.0, -3.0], [1.0, 0.0, 0.0, 0.0])
            rec.rotors(t, [390.0] * 4)
        rec.armed(1.0, True)
        rec.flight_mode(1.0, "AUTO.TAKEOFF")
        rec.flight_mode(4.0, "OFFBOARD")
        rec.strategy_state(4.0, "acquire")
        rec.strategy_state(8.0, "verify")
        rec.strategy_state(11.0, "surge")
        rec.strategy_state(12.0, "verify")
        rec.declare(15.0, [2.0, 0.0, -1.5], 0.8)
        rec.flight_mode(17.0, "AUTO.LAND")
        rec.armed(19.5, False)
    log = RrdLog(path)
    t, v = log.scalars("markers/phase")
    np.testing.assert_allclose(t, np.repeat([1.0, 4.0, 17.0, 19.5], 3))  # take-off, search, landing, landed
    np.testing.assert_array_equal(v[0::3], -MARKER_SPAN)
    np.testing.assert_array_equal(v[1::3], MARKER_SPAN)
    assert np.isnan(v[2::3]).all()  # NaN breaks the line between two markers
    np.testing.assert_allclose(log.scalars("markers/verify")[0][0::3], [8.0, 12.0])
    np.testing.assert_allclose(log.scalars("markers/declared")[0][0::3], [15.0])
    assert [s for _, s in log.states("phases/mission")] == ["armed", "take-off", "search", "verify", "search",
                                                             "verify", "descend", "landing", "landed"]  # fmt: skip
    s = log.summary()
    assert s is not None and s.t_arm_s == 1.0 and s.t_search_s == 4.0 and s.t_declared_s == 15.0
    assert [v["t_start_s"] for v in s.verifications] == [8.0, 12.0]
    lay = log.layout()
    assert lay is not None and lay.markers and lay.t_range == pytest.approx((0.0, 19.9))
