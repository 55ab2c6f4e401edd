"""The magnetometer's Earth field is the World Magnetic Model's at the scenario's home (vehicle/geomag.py),
the field PX4's and ArduPilot's EKFs assume there; a field in the scenario file is kept."""

from __future__ import annotations

import math

import pytest

from sitl.scenario import ScenarioError, parse_scenario
from sitl.world.sensors import HomeConfig, MagConfig
from vehicle.geomag import earth_field_ned_gauss


def _declination_inclination(f: tuple[float, float, float]) -> tuple[float, float]:
    n, e, d = f
    return math.degrees(math.atan2(e, n)), math.degrees(math.atan2(d, math.hypot(n, e)))


def test_default_field_is_the_wmm_at_px4s_default_home():
    f = earth_field_ned_gauss(HomeConfig.lat_deg, HomeConfig.lon_deg, HomeConfig.alt_m)
    assert f == MagConfig().field_ned_gauss
    dec, inc = _declination_inclination(f)
    # PX4's own table (WMM-2020 at 2024.4) reads 3.41 deg / 63.16 deg there; ArduPilot's 3.19 / 63.11.
    assert dec == pytest.approx(3.42, abs=0.02) and inc == pytest.approx(63.50, abs=0.05)
    assert math.hypot(*f) == pytest.approx(0.4832, abs=5e-4)


def _scenario(sensors: dict) -> dict:
    return {"name": "t", "duration_s": 1.0, "sensors": sensors}


def test_a_scenario_elsewhere_gets_its_own_field_and_a_given_field_is_kept():
    sydney = {"home": {"lat_deg": -33.8688, "lon_deg": 151.2093, "alt_m": 20.0}}
    f = parse_scenario(_scenario(sydney)).sensors.mag.field_ned_gauss
    dec, inc = _declination_inclination(f)
    assert 12.0 < dec < 13.5 and -66.0 < inc < -63.0, (dec, inc)  # east declination, field pointing up
    given = {**sydney, "mag": {"field_ned_gauss": [0.2, 0.0, 0.4]}}
    assert parse_scenario(_scenario(given)).sensors.mag.field_ned_gauss == (0.2, 0.0, 0.4)
    with pytest.raises(ScenarioError, match="sensors.home"):
        parse_scenario(_scenario({"home": {"lat_deg": 95.0, "lon_deg": 0.0}}))
