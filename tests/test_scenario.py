"""Scenario files: built-ins load, the paper's winds are converted, bad input names the field."""

import math

import pytest

from sitl.scenario import ScenarioError, builtin_scenarios, load_scenario, parse_scenario


def test_builtins_load():
    names = builtin_scenarios()
    assert {"paper-s1", "paper-s2"} <= set(names)
    for n in names:
        assert load_scenario(n).name == n


def test_paper_s1_wind_is_air_mass_velocity():
    sc = load_scenario("paper-s1")
    # Paper [10, 0, 0] (added to ground velocity) is air moving south: from the north.
    assert sc.wind.velocity_ned == (-10.0, 0.0, 0.0)
    assert sc.wind.changes[0].t_s == 23.0
    assert sc.wind.changes[0].velocity_ned == (-7.07, -7.07, -3.0)
    assert sc.turbulence is not None and sc.turbulence.sigma_u == 1.0


def test_speed_and_from_direction():
    sc = parse_scenario({"name": "x", "wind": {"speed_m_s": 7.0, "from_deg": 45.0, "profile": "log"}})
    vn, ve, vd = sc.wind.velocity_ned
    assert vn == pytest.approx(-7 / math.sqrt(2)) and ve == pytest.approx(-7 / math.sqrt(2)) and vd == 0.0
    assert sc.wind.profile == "log"


def test_file_round_trip(tmp_path):
    p = tmp_path / "my.toml"
    p.write_text('name = "mine"\nduration_s = 5\n[wind]\nspeed_m_s = 3.0\nfrom_deg = 90\n')
    sc = load_scenario(p)
    assert sc.name == "mine" and sc.duration_s == 5.0
    assert sc.wind.velocity_ned[1] == pytest.approx(-3.0)


@pytest.mark.parametrize(
    ("doc", "field"),
    [
        ({"wind": {"velocity_ned": [1, 2]}}, "wind.velocity_ned"),
        ({"wind": {"velocity_ned": [1, 2, 3], "speed_m_s": 3}}, "wind"),
        ({"wind": {"speed_m_s": 500, "from_deg": 0}}, "wind.speed_m_s"),
        ({"wind": {"velocity_ned": [0, 0, 0], "profile": "power"}}, "wind.profile"),
        ({"turbulence": {"level": "extreme"}}, "turbulence.level"),
        ({"turbulence": {"sigma_u_m_s": -1}}, "turbulence.sigma_u_m_s"),
        ({"turbulence": {"intensity_class": "D"}}, "turbulence.intensity_class"),
        ({"duration_s": -3}, "duration_s"),
        ({"physics": {"rate_hz": 10}}, "physics.rate_hz"),
        ({"sensors": {"imu": {"rate_hz": 333}}}, "sensors.imu.rate_hz"),
        ({"sensors": {"imu": {"gyro_noise": 1}}}, "sensors.imu"),
        ({"route": {"waypoints": [{"position_ned": [0, 0, 5]}]}}, "route.waypoints[0].position_ned[2]"),
        ({"start": {"position_ned": [0, 0, -5]}}, "start.position_ned[2]"),
        ({"controller": {"tilt_max_deg": 95}}, "controller.tilt_max"),
        ({"colour": "red"}, "colour"),
        ({"seed": "abc"}, "seed"),
    ],
)
def test_errors_name_the_field(doc, field):
    with pytest.raises(ScenarioError) as e:
        parse_scenario({"name": "bad", **doc})
    assert field in str(e.value)


def test_unknown_scenario_lists_builtins():
    with pytest.raises(ScenarioError, match="paper-s1"):
        load_scenario("no-such-scenario")


def test_toml_syntax_error(tmp_path):
    p = tmp_path / "broken.toml"
    p.write_text("name = \n")
    with pytest.raises(ScenarioError, match="TOML"):
        load_scenario(p)
