"""Tests for sitl.world.plume.setup and .part: [plume] parsing, the plume + chemical sensor in the lockstep
simulation, and the plume scenarios (SI, NED; concentration in mg/m^3)."""

from __future__ import annotations

import copy
import tomllib
from dataclasses import replace
from importlib import resources
from typing import Any

import numpy as np
import pytest

from sitl.scenario import ScenarioError, builtin_scenarios, load_scenario, parse_scenario
from sitl.simulation import Simulation
from sitl.world.chem_sensor import ChemReading
from sitl.world.plume import PuffPlume, puffs
from sitl.world.plume.setup import parse_plume_table
from windseek.cmd_sim import simulate


def _open_field_data() -> dict[str, Any]:
    text = (resources.files("sitl") / "scenarios" / "open-field.toml").read_text()
    return tomllib.loads(text)


def _with_plume(**changes: Any) -> dict[str, Any]:
    data = copy.deepcopy(_open_field_data())
    for key, value in changes.items():
        if key.startswith("sensor_"):
            data["plume"]["sensor"][key[len("sensor_") :]] = value
        else:
            data["plume"][key] = value
    return data


@pytest.mark.parametrize(
    ("changes", "field", "allowed"),
    [
        ({"stability": "G"}, "plume.stability", "A-F"),
        ({"model": "lagrangian"}, "plume.model", "'puff', 'gaussian'"),
        ({"update_rate_hz": 7.0}, "plume.update_rate_hz", "50/n Hz"),
        ({"sensor_sample_rate_hz": 3.0}, "plume.sensor.sample_rate_hz", "50/n Hz"),
        ({"sensor_time_constant_s": 0.0}, "plume.sensor.time_constant_s", "> 0"),
        ({"max_puffs": 0}, "plume.max_puffs", "integers"),
        ({"warmup_s": -1.0}, "plume.warmup_s", "allowed range"),
        ({"sources": []}, "plume.sources", "non-empty list"),
        ({"sources": [{"position_ned": [0.0, 0.0, 1.0], "rate_g_s": 1.0}]}, "plume.sources[0].position_ned[2]", "<= 0"),
        ({"sources": [{"position_ned": [0.0, 0.0, -1.0]}]}, "plume.sources[0].rate_g_s", "required"),
        ({"colour": "blue"}, "plume", "allowed: domain_max_ned"),
    ],
)
def test_bad_plume_table_fails_at_load_naming_the_field(changes: dict, field: str, allowed: str) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(_with_plume(**changes), "test.toml")
    assert field in str(err.value) and allowed in str(err.value)


def test_rates_must_divide_the_mode_rate() -> None:
    tbl = _open_field_data()["plume"]
    assert parse_plume_table({**tbl, "update_rate_hz": 25.0}).plume.update_rate_hz == 25.0
    # A 20 Hz mode tick admits 20/n Hz only.
    with pytest.raises(ScenarioError, match="update_rate_hz"):
        parse_plume_table({**tbl, "update_rate_hz": 25.0}, mode_rate_hz=20.0)
    # Sources default to emitting since the start of the warm-up.
    setup = parse_plume_table(tbl)
    assert setup.warmup_s == 120.0 and setup.plume.sources[0].start_s == -120.0


def test_simulate_open_field_reports_plume_figures_and_is_deterministic() -> None:
    a = simulate("open-field", 20.0, seed=3)
    b = simulate("open-field", 20.0, seed=3)
    c = simulate("open-field", 20.0, seed=4)
    assert a["plume_puffs"] == 1000  # warm-up filled the cap (120 s at 10 Hz)
    assert a["chem_peak"] > 0.0
    assert 0.0 < a["chem_detect_fraction"] <= 1.0  # the start is inside the plume
    assert a["chem_samples"] == 200  # 20 s at 10 Hz
    timing = {"wall_time_s", "realtime_factor"}
    assert {k: v for k, v in a.items() if k not in timing} == {k: v for k, v in b.items() if k not in timing}
    assert (a["chem_peak"], a["chem_detect_fraction"]) != (c["chem_peak"], c["chem_detect_fraction"])


def test_chem_readings_are_drained_at_the_sensor_rate() -> None:
    sim = Simulation(load_scenario("open-field"), seed=1)
    assert isinstance(sim.plume, PuffPlume) and sim.plume.t == 0.0
    sim.run_until(5.0)
    chem = sim.drain()["chem"]
    assert all(isinstance(r, ChemReading) for r in chem)
    times = np.array([r.t for r in chem])
    np.testing.assert_allclose(times, 0.1 * np.arange(50), atol=1e-9)
    assert sim.chem.latest is chem[-1]
    assert sim.plume.t == pytest.approx(4.9)  # advanced at 10 Hz, to the last due tick
    assert sim.drain()["chem"] == []  # drained
    sim.run_until(6.0)
    assert [round(r.t, 6) for r in sim.drain()["chem"]] == [round(5.0 + 0.1 * i, 6) for i in range(10)]


def test_sensor_rate_and_step_grouping() -> None:
    """25 Hz sensor: readings every 2 mode ticks; the readings do not depend on how the
    physics ticks are grouped into step() calls."""
    sc = parse_scenario(_with_plume(sensor_sample_rate_hz=25.0, sensor_noise_std_mg_m3=0.05), "test.toml")
    runs = []
    for chunk in (1, 37):
        sim = Simulation(sc, seed=2)
        while sim.t < 2.0 - 1e-9:
            sim.step(min(chunk, round((2.0 - sim.t) / sim.dt)))
        runs.append([(r.t, r.value_mg_m3) for r in sim.drain()["chem"]])
    assert runs[0] == runs[1]
    np.testing.assert_allclose([t for t, _ in runs[0]], 0.04 * np.arange(50), atol=1e-9)


def test_warmup_forms_the_plume_before_t0() -> None:
    sources = [{"position_ned": [60.0, 0.0, -2.0], "rate_g_s": 1.0, "start_s": 0.0}]
    cold = Simulation(parse_scenario(_with_plume(sources=sources), "test.toml"), seed=1)
    assert len(cold.plume.puffs) == 0  # the source switches on at t = 0
    warm = Simulation(parse_scenario(_with_plume(warmup_s=30.0), "test.toml"), seed=1)
    assert len(warm.plume.puffs) == 300  # 30 s at 10 puffs/s
    assert warm.plume.puffs[:, 0].min() < 0.0  # and it has already reached past the start


def test_paper_s1_has_no_chemical_output() -> None:
    sim = Simulation(load_scenario("paper-s1"), seed=1)
    sim.run(1.0)
    assert "chem" not in sim.drain()
    assert sim.plume is None and sim.chem is None
    assert not any(k.startswith(("plume_", "chem_")) for k in sim.summary_extras())


def test_plume_scenarios_load() -> None:
    names = {"open-field", "open-field-low", "open-field-high", "open-field-stable", "open-field-unstable",
             "open-field-shift", "open-field-far", "paper-anemotaxis"}  # fmt: skip
    assert names <= set(builtin_scenarios())
    for name in names:
        sc = load_scenario(name)
        assert sc.plume is not None and sc.duration_s == 300.0 and sc.route.takeoff_altitude_m == 5.0
    assert load_scenario("open-field-stable").plume.plume.stability == "F"
    assert load_scenario("open-field-unstable").plume.plume.stability == "A"
    # The far start differs from open-field in the source distance only.
    far, near = load_scenario("open-field-far"), load_scenario("open-field")
    assert far.plume.plume.sources[0].position_ned == (120.0, 0.0, -2.0)
    assert replace(far.plume, plume=replace(far.plume.plume, sources=near.plume.plume.sources)) == near.plume
    assert far.wind == near.wind
    shift = load_scenario("open-field-shift").wind
    v0, v1 = shift.velocity_ned, shift.changes[0].velocity_ned
    turn = np.degrees(np.arctan2(v1[1], v1[0]) - np.arctan2(v0[1], v0[0]))
    assert 30.0 <= abs(turn) <= 40.0


def test_gaussian_model_attaches() -> None:
    sim = Simulation(parse_scenario(_with_plume(model="gaussian"), "test.toml"), seed=1)
    sim.run_until(1.0)
    assert len(sim.drain()["chem"]) == 10
    assert sim.summary_extras()["plume_puffs"] == 0


def test_puff_concentration_kernel_matches_the_closed_form_sum() -> None:
    """The fused kernel is the sum of ground-reflected isotropic Gaussian puffs."""
    sim = Simulation(load_scenario("open-field"), seed=5, autostart_route=False)
    plume = sim.plume
    pts = np.array([[x, y, z] for x in (0.0, 20.0, 45.0, 59.0) for y in (-3.0, 0.0, 2.0) for z in (0.0, -2.0, -5.0)])
    p = plume.puffs  # physical x, y, z NED and r^2
    mass = plume.mass_in_puffs_g / len(p)  # equal masses: one source, constant rate
    r2 = p[:, 3]
    dh2 = (pts[:, None, 0] - p[:, 0]) ** 2 + (pts[:, None, 1] - p[:, 1]) ** 2
    zq, zp = -pts[:, None, 2], -p[:, 2]
    g = np.exp(-0.5 * (dh2 + (zq - zp) ** 2) / r2) + np.exp(-0.5 * (dh2 + (zq + zp) ** 2) / r2)
    ref = g @ (mass * 1000.0 / ((2.0 * np.pi) ** 1.5 * r2**1.5))
    got = plume.concentration(pts)
    assert ref.max() > 1.0  # the check covers points inside the plume
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    assert plume.concentration(pts[4]) == pytest.approx(ref[4], rel=1e-12, abs=1e-12)


def test_a_grid_culls_puffs_without_changing_a_single_bit() -> None:
    """A grid of points (a recorded slice) first culls the puffs against its bounding box: every
    value is bit for bit the one of the same point asked alone (no culling). The grid is a small
    window inside the plume, so puffs just outside it still reach its edge points (a cull that
    dropped them would change those values), and most puffs are far downwind of it."""
    sim = Simulation(load_scenario("open-field"), seed=5, autostart_route=False)
    sim.run_until(40.0)
    plume = sim.plume
    xs, ys = np.linspace(30.0, 40.0, 11), np.linspace(-1.0, 1.0, 5)
    grid = np.array([[x, y, -2.0] for x in xs for y in ys])
    assert len(grid) >= puffs.CULL_MIN_POINTS
    lo, hi = grid[:, :2].min(axis=0), grid[:, :2].max(axis=0)
    p = plume.puffs
    outside = ((p[:, :2] < lo - 10.0 * np.sqrt(p[:, 3:4])) | (p[:, :2] > hi + 10.0 * np.sqrt(p[:, 3:4]))).any(axis=1)
    assert outside.mean() > 0.3  # the cull has puffs to drop
    got = plume.concentration(grid)
    alone = np.array([plume.concentration(q) for q in grid])
    assert got.max() > 1.0  # the grid crosses the plume
    assert np.array_equal(got, alone)
