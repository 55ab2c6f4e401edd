"""The urban world: buildings shape the wind the vehicle and the plume feel, a flight into a building
is a crash, puffs never end inside a building (small grids: fast)."""

from __future__ import annotations

import numpy as np
import pytest

from sitl.scenario import ScenarioError, parse_scenario
from sitl.simulation import Simulation

CUBE = {  # one 10 m cube, wind 6 m/s from the north: its lee is to the south (smaller north)
    "name": "cube-test", "duration_s": 60.0,
    "wind": {"speed_m_s": 6.0, "from_deg": 0.0, "profile": "log"},
    "turbulence": {"level": "low"},
    "start": {"position_ned": [20.0, 30.0, 0.0]},
    "urban": {"grid": {"x_min_m": 0.0, "y_min_m": 0.0, "length_x_m": 110.0, "length_y_m": 70.0,
                       "height_m": 40.0, "spacing_m": 2.0},
              "buildings": [{"type": "box", "x_m": 70.0, "y_m": 30.0, "length_m": 10.0, "width_m": 10.0,
                             "height_m": 10.0}]},
}  # fmt: skip


def test_the_cube_shapes_the_wind_and_stays_solid(tmp_path: object) -> None:
    sim = Simulation(parse_scenario(CUBE), seed=1, autostart_route=False)
    w = sim.wind
    upstream = w.mean(0.0, np.array([100.0, 30.0, -5.0]))
    lee = w.mean(0.0, np.array([60.0, 30.0, -5.0]))  # 5 m behind the lee face
    inside = w.velocity(0.0, np.array([70.0, 30.0, -5.0]))
    assert upstream[0] == pytest.approx(-6.0 * np.log(5 / 0.1) / np.log(10 / 0.1), rel=0.05)
    assert lee[0] > -0.5 * abs(upstream[0])  # sheltered (or reversed) behind the cube
    assert np.array_equal(inside, np.zeros(3))  # no air moves inside a building, turbulence neither
    assert w.kernel() is not None and w.kernel().urban_on  # the fast path: the world's compiled loop


def test_flying_into_the_building_is_a_crash() -> None:
    sim = Simulation(parse_scenario(CUBE), seed=2, autostart_route=False)
    fc = sim.fc
    sim.run(1.0)
    assert fc.arm()[0] and fc.takeoff(5.0)[0]
    sim.run(8.0)
    assert not sim.crashed
    fc.reposition(np.array([75.0, 30.0, -5.0]))  # into the cube's north half, at 5 m
    sim.run(30.0)
    assert sim.crashed and sim.world.collisions >= 1
    pos = sim.position
    assert not (65.0 < pos[0] < 75.0 and 25.0 < pos[1] < 35.0 and -pos[2] < 10.0)  # stopped at the wall


def test_puffs_never_end_inside_a_building() -> None:
    source = {"position_ned": [95.0, 30.0, -4.0], "rate_g_s": 1.0}
    sc = parse_scenario({**CUBE, "plume": {"warmup_s": 30.0, "update_rate_hz": 10.0, "sources": [source]}})
    sim = Simulation(sc, seed=3, autostart_route=False)
    sim.run(20.0)
    puffs = sim.chem.puff_array()
    assert puffs is not None and len(puffs) > 100
    inside = (np.abs(puffs[:, 0] - 70.0) < 5.0) & (np.abs(puffs[:, 1] - 30.0) < 5.0) & (-puffs[:, 2] < 10.0)
    assert not inside.any()
    assert sim.plume.reflected > 0  # the plume went through the cube's place and was turned away


@pytest.mark.parametrize(
    ("change", "says"),
    [
        ({"wind": {"speed_m_s": 6.0, "from_deg": 0.0}}, "profile = 'log'"),
        ({"wind": {"speed_m_s": 6.0, "from_deg": 0.0, "profile": "log",
                   "changes": [{"t_s": 10.0, "speed_m_s": 3.0, "from_deg": 90.0}]}}, "no changes"),
        ({"urban": {**CUBE["urban"], "buildings": [{"type": "box", "x_m": 70.0, "y_m": 30.0, "length_m": 10.0,
                                                   "width_m": 10.0, "height_m": -3.0}]}},
         "urban.buildings[0].height_m"),
        ({"urban": {"buildings": []}}, "urban.grid"),
    ],
)  # fmt: skip
def test_urban_scenario_errors_name_the_field(change: dict, says: str) -> None:
    with pytest.raises(ScenarioError, match=says.replace("[", r"\[").replace("]", r"\]")):
        parse_scenario({**CUBE, **change})


def test_paper_s4_layout_is_what_its_file_says() -> None:
    """The reconstructed Scenario 4 (assumed layout, see the file): start downwind of the source,
    six buildings between them, neither the start nor the source inside a building."""
    from sitl.scenario import load_scenario
    from urbanflow.geometry import BuildingArrays, inside_many

    sc = load_scenario("paper-s4")
    assert sc.urban is not None and len(sc.urban.buildings) == 6 and sc.wind_model == "urban"
    start = np.array([*sc.start.position_ned[:2], -5.0])
    src = np.array(sc.plume.plume.sources[0].position_ned)  # type: ignore[union-attr]
    arrays = BuildingArrays.from_buildings(sc.urban.buildings)
    assert not inside_many(np.array([start, src]), *arrays.args()).any()
    upwind = np.radians(45.0)  # wind from 45 deg: the source lies toward it from the start
    d = src[:2] - start[:2]
    assert np.hypot(*d) == pytest.approx(125.0, abs=1.0) and abs(np.arctan2(d[1], d[0]) - upwind) < 0.02
    # Every building is between them: its centre projects onto the start-source segment.
    for b in sc.urban.buildings:
        t = float(np.dot(np.array([b.x_m, b.y_m]) - start[:2], d) / np.dot(d, d))
        assert 0.2 < t < 0.8, b


@pytest.mark.parametrize("name", ["paper-s4-street", "paper-s4-wind90", "paper-s4-courtyard"])
def test_urban_variants_keep_the_source_upwind_and_clear_of_buildings(name: str) -> None:
    """Each variant (issue 20): start and source in the air, outside every building, the source
    upwind of the start (within 20 deg of the wind's from-direction)."""
    from sitl.scenario import load_scenario
    from urbanflow.geometry import BuildingArrays, inside_many

    sc = load_scenario(name)
    assert sc.urban is not None and sc.plume is not None and sc.wind_model == "urban"
    start = np.array([*sc.start.position_ned[:2], -5.0])
    src = np.array(sc.plume.plume.sources[0].position_ned)
    assert not inside_many(np.array([start, src]), *BuildingArrays.from_buildings(sc.urban.buildings).args()).any()
    d = src[:2] - start[:2]
    bearing = np.degrees(np.arctan2(d[1], d[0]))
    assert abs((bearing - sc.urban.wind.from_deg + 180.0) % 360.0 - 180.0) < 20.0
    assert 80.0 < np.hypot(*d) < 160.0


@pytest.mark.parametrize("name", ["paper-s4-wind90", "paper-s4-courtyard"])
def test_urban_variant_fields_are_mass_consistent_on_a_coarse_grid(name: str) -> None:
    """The variants' fields solve (5 m cells here, to stay fast) to a divergence-free field; the
    courtyard's air recirculates: the flow at its centre runs back toward the closed (upwind) side."""
    from dataclasses import replace

    from sitl.scenario import load_scenario
    from sitl.world.urban import solve_urban_wind

    sc = load_scenario(name)
    assert sc.urban is not None and sc.plume is not None
    field = solve_urban_wind(replace(sc.urban, grid=replace(sc.urban.grid, spacing_m=5.0)))
    assert field.max_divergence_ratio() < 1e-3
    if name == "paper-s4-courtyard":
        src = np.array(sc.plume.plume.sources[0].position_ned)
        assert field.mean(np.array([[src[0], src[1], -4.0]]))[0, 0] > 0.5  # wind from the north: reversed


@pytest.mark.parametrize(
    ("field", "position"),
    [("start.position_ned", [70.0, 30.0, 0.0]), ("plume.sources[0].position_ned", [72.0, 28.0, -4.0])],
)
def test_start_or_source_inside_a_building_is_named(field: str, position: list[float]) -> None:
    doc: dict = {**CUBE, "plume": {"sources": [{"position_ned": [95.0, 30.0, -4.0], "rate_g_s": 1.0}]}}
    if field.startswith("start"):
        doc["start"] = {"position_ned": position}
    else:
        doc["plume"] = {"sources": [{"position_ned": position, "rate_g_s": 1.0}]}
    with pytest.raises(ScenarioError, match=field.replace("[", r"\[").replace("]", r"\]") + ".*inside building"):
        parse_scenario(doc)
