"""The Rerun recorder: real .rrd files written and read back with ``rerun.chunk.RrdReader``.

One 15 s open-field simulation is recorded through ``record_simulation`` (module fixture)
and checked against the simulation itself; the recorder methods the estimator and the
strategies use are checked with known values.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from recording.read import RrdLog
from recording.rerun_log import RunRecorder, log_colormap
from recording.sim_hook import record_simulation, wind_speed_from_deg
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


def test_sim_recording_has_expected_entities_on_sim_time(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    temporal = set(log.temporal_entity_paths())
    expected = {
        "world/vehicle", "world/trail", "world/wind/truth", "world/plume/slice", "world/plume/puffs",
        "wind/north/truth", "wind/east/truth", "wind/down/truth", "wind/speed/truth", "wind/direction/truth",
        "rotors/1", "rotors/2", "rotors/3", "rotors/4", "chem/value", "log/events",
    }  # fmt: skip
    assert expected <= temporal, expected - temporal
    # Static: coordinate convention, vehicle geometry, true source.
    assert {"world", "world/vehicle/body", "world/vehicle/axes", "world/sources/true"} <= set(log.entity_paths())
    # No estimator ran: its entities carry a style only, no data.
    assert "wind/north/estimate" not in temporal
    # Wall-clock log_time is switched off: the simulation timeline only.
    assert log.timelines() == {"sim_time"}
    assert log.application_ids == ["windseek"]


def test_vehicle_pose_and_trail(sim_run: tuple[Simulation, RrdLog]) -> None:
    sim, log = sim_run
    t, pos = log.vectors("world/vehicle", "Transform3D:translation")
    # 25 Hz from t = 0 over 15 s (the last hook call is at the last mode tick before 15 s).
    assert len(t) == 375
    np.testing.assert_allclose(np.diff(t), 0.04, atol=1e-9)
    assert t[0] == 0.0 and t[-1] == pytest.approx(DURATION_S - 0.04)
    # Starts on the ground, climbs to the route's 5 m (altitude = -z) without overshooting much.
    assert pos[0, 2] == pytest.approx(0.0, abs=0.05)
    assert -pos[-1, 2] == pytest.approx(5.0, abs=0.3)
    assert -pos[:, 2].min() < 5.6
    np.testing.assert_allclose(pos[-1], sim.position, atol=0.05)  # within one logging period of flight
    _, quat = log.column("world/vehicle", "Transform3D:quaternion")
    q = np.array([np.ravel(v) for v in quat])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
    _, strips = log.column("world/trail", "LineStrips3D:strips")
    last = np.array(strips[-1][0])
    assert last.shape[1] == 3 and len(last) >= 10
    assert -last[:, 2].min() > 4.0  # the trail reaches flight altitude


def test_rotor_speeds_in_range_when_flying(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    t_pos, pos = log.vectors("world/vehicle", "Transform3D:translation")
    flying = t_pos[-pos[:, 2] > 1.0]
    assert len(flying) > 200
    for i in range(1, 5):
        t, w = log.scalars(f"rotors/{i}")
        np.testing.assert_array_equal(t, t_pos)
        w_fly = w[np.isin(t, flying)]
        assert w_fly.min() >= 100.0 and w_fly.max() <= 600.0
        # Hover is 393 rad/s; in 5 m/s wind the mean stays near it.
        assert w_fly.mean() == pytest.approx(393.0, abs=30.0)


def test_wind_truth_matches_the_wind_field(sim_run: tuple[Simulation, RrdLog]) -> None:
    sim, log = sim_run
    t, n = log.scalars("wind/north/truth")
    _, e = log.scalars("wind/east/truth")
    _, d = log.scalars("wind/down/truth")
    t_pos, pos = log.vectors("world/vehicle", "Transform3D:translation")
    np.testing.assert_array_equal(t, t_pos)
    # The wind field is a deterministic function of (t, position): evaluate it again at the
    # logged times and positions (float32 positions: tiny differences only).
    again = np.array([sim.wind.velocity(ti, p.astype(float)) for ti, p in zip(t, pos, strict=True)])
    np.testing.assert_allclose(np.column_stack([n, e, d]), again, atol=2e-3)
    # Open field: 5 m/s from the north (air going south) with moderate turbulence.
    assert n.mean() == pytest.approx(-5.0, abs=1.5)
    assert abs(e.mean()) < 1.5
    speed = np.hypot(n, e)
    assert 3.5 < speed.mean() < 6.5
    t_s, s = log.scalars("wind/speed/truth")
    _, from_deg = log.scalars("wind/direction/truth")
    np.testing.assert_allclose(s, speed, rtol=1e-9)
    assert ((from_deg >= 0.0) & (from_deg < 360.0)).all()
    circ_mean = math.degrees(math.atan2(np.sin(np.radians(from_deg)).mean(), np.cos(np.radians(from_deg)).mean()))
    assert abs(circ_mean) < 25.0
    _, arrows = log.column("world/wind/truth", "Arrows3D:vectors")
    np.testing.assert_allclose(np.array([a[0] for a in arrows]), np.column_stack([n, e, d]), atol=1e-5)


def test_chem_readings_match_the_sensor(sim_run: tuple[Simulation, RrdLog]) -> None:
    sim, log = sim_run
    t, c = log.scalars("chem/value")
    model = sim.chem
    assert len(c) == model.n_samples == 150  # every 10 Hz reading, none dropped or doubled
    np.testing.assert_allclose(np.diff(t), 0.1, atol=1e-9)
    assert (c >= 0.0).all()
    assert c.max() == pytest.approx(model.peak_mg_m3, rel=1e-9)
    assert (c > 0).sum() == model.n_detected > 0  # 60 m downwind of the source: inside the plume


def test_plume_slice_and_puffs(sim_run: tuple[Simulation, RrdLog]) -> None:
    sim, log = sim_run
    t, slices = log.column("world/plume/slice", "Points3D:positions")
    assert len(t) == 8  # 0.5 Hz over 15 s: t = 0, 2, ..., 14
    t_pos, pos = log.vectors("world/vehicle", "Transform3D:translation")
    for ti, pts in zip(t, slices, strict=True):
        p = np.array(pts)
        assert len(p) > 10
        # Default bounds: source (60, 0) and start (0, 0) with a 30 m margin.
        assert p[:, 0].min() >= -30.0 and p[:, 0].max() <= 90.0 and np.abs(p[:, 1]).max() <= 30.0
        # At the vehicle's altitude, or the 5 m take-off altitude while still on the ground.
        z_vehicle = pos[np.searchsorted(t_pos, ti), 2]
        assert np.ptp(p[:, 2]) == 0.0
        assert p[0, 2] == pytest.approx(z_vehicle if z_vehicle < -0.5 else -5.0, abs=1e-5)
    _, colors = log.column("world/plume/slice", "Points3D:colors")
    assert len(colors[-1]) == len(slices[-1])
    t_p, puffs = log.column("world/plume/puffs", "Points3D:positions")
    _, radii = log.column("world/plume/puffs", "Points3D:radii")
    assert len(t_p) == 30
    assert len(puffs[-1]) == sim.chem.n_puffs
    assert min(radii[-1]) > 0.0
    _, src = log.column("world/sources/true", "Points3D:positions")
    np.testing.assert_allclose(src[0], [[60.0, 0.0, -2.0]])


def test_mode_changes_logged_as_text(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    _, texts = log.column("log/events", "TextLog:text")
    flat = [x[0] for x in texts]
    assert "mode MISSION" in flat and "armed" in flat


def test_blueprint_layout(sim_run: tuple[Simulation, RrdLog]) -> None:
    _, log = sim_run
    assert log.blueprint_count == 1
    views = {(cls, origin) for cls, origin, _ in log.blueprint_views()}
    assert ("3D", "world") in views and ("TextLog", "log") in views
    for origin in ("wind/north", "wind/east", "wind/down", "wind/speed", "wind/direction", "chem", "rotors"):
        assert ("TimeSeries", origin) in views
    assert "time_panel" in log.blueprint_entity_paths()


def test_recorder_methods_with_known_values(tmp_path: Path) -> None:
    path_a, path_b = tmp_path / "a.rrd", tmp_path / "b.rrd"
    # Two recorders at once, in one process: separate streams, separate files and ids.
    with RunRecorder(path_a, strategy="zigzag", series_flush_s=0.3) as a, RunRecorder(path_b, blueprint=False) as b:
        for k in range(20):
            t = 0.1 * k
            a.wind(t, truth_ned=[-5.0, 0.0, 0.0], est_ned=[-4.0, 1.0, 0.5], sigma_ned=[0.5, 0.25, 0.1])
            a.wind_speed_dir(t, 5.0, -10.0 if k else math.nan, dir_filt_deg=370.0)
            a.chem(t, 0.2 * k, 1.0)
            b.rotors(t, [400.0 + k, 401.0, 402.0, 403.0])
        a.sources([[10.0, 0.0, -1.0]], declared_ned=[9.0, 1.0, -1.0], confidence=0.9)
        a.geofence([-20.0, -20.0, -30.0], [20.0, 20.0, 0.0])
        a.text(1.0, "surge", "warn", channel="strategy")
        with pytest.raises(ValueError, match="level"):
            a.text(1.0, "x", "LOUD")
    la, lb = RrdLog(path_a), RrdLog(path_b)
    t, lo = la.scalars("wind/north/lower")
    _, hi = la.scalars("wind/north/upper")
    assert len(t) == 20 and t[-1] == pytest.approx(1.9)  # rows from all flushes, in order
    np.testing.assert_allclose(lo, -5.0)  # -4 - 2 * 0.5
    np.testing.assert_allclose(hi, -3.0)
    np.testing.assert_allclose(la.scalars("wind/east/upper")[1], 1.5)
    _, raw = la.scalars("wind/direction/raw")
    assert len(raw) == 19  # the NaN sample is a gap, not a point
    np.testing.assert_allclose(raw, 350.0)  # wrapped to [0, 360)
    np.testing.assert_allclose(la.scalars("wind/direction/filtered")[1], 10.0)
    np.testing.assert_allclose(la.scalars("chem/value")[1], 0.2 * np.arange(20))
    t_dec, lab = la.column("world/sources/declared", "Points3D:labels")
    assert lab == [["declared (90%)"]] and t_dec[0] == pytest.approx(1.9)  # at the latest time logged
    _, lvl = la.column("log/strategy", "TextLog:level")
    assert lvl == [["WARN"]]
    assert "world/geofence" in la.entity_paths()
    np.testing.assert_allclose(lb.scalars("rotors/1")[1], 400.0 + np.arange(20))
    assert "rotors/1" not in la.temporal_entity_paths() and "wind/north/lower" not in lb.temporal_entity_paths()
    assert lb.blueprint_count == 0 and la.blueprint_count == 1


def test_wind_from_direction_and_colormap() -> None:
    assert wind_speed_from_deg(np.array([-5.0, 0.0, 0.0])) == pytest.approx((5.0, 0.0))  # from north
    assert wind_speed_from_deg(np.array([0.0, -3.0, 1.0]))[1] == pytest.approx(90.0)  # from east
    assert wind_speed_from_deg(np.array([0.0, 3.0, 0.0]))[1] == pytest.approx(270.0)
    rgb = log_colormap(np.array([0.0, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1e4]), 1e-2, 1e2)
    # Log scale: each decade is one quarter of the map; clipped at both ends.
    assert (rgb[0] == rgb[1]).all() and (rgb[-1] == rgb[-2]).all()
    np.testing.assert_array_equal(rgb[1], [68, 1, 84])
    np.testing.assert_array_equal(rgb[3], [33, 145, 140])
    np.testing.assert_array_equal(rgb[5], [253, 231, 37])


def test_trail_is_thinned_but_keeps_start_and_end(tmp_path: Path) -> None:
    path = tmp_path / "trail.rrd"
    with RunRecorder(path, trail_max_points=10, trail_every_s=0.0) as rec:
        for k in range(50):
            rec.vehicle(0.1 * k, [float(k), 0.0, -5.0], [1.0, 0.0, 0.0, 0.0])
    t, strips = RrdLog(path).column("world/trail", "LineStrips3D:strips")
    last = np.array(strips[-1][0])
    assert len(last) <= 11
    np.testing.assert_allclose(last[0], [0.0, 0.0, -5.0])
    np.testing.assert_allclose(last[-1], [49.0, 0.0, -5.0])
    assert (np.diff(last[:, 0]) > 0).all()  # still in flight order
    assert t[-1] == pytest.approx(4.9)
