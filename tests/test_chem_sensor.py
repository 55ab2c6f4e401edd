"""Tests for sitl.world.chem_sensor (concentrations in mg/m^3, times in s)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.world.chem_sensor import ChemicalSensor, ChemSensorConfig


def _run(sensor: ChemicalSensor, conc: float, n: int, dt: float, t0: float = 0.0) -> list:
    return [sensor.sample(t0 + i * dt, conc) for i in range(n)]


def test_step_response_reaches_63_percent_after_tau() -> None:
    cfg = ChemSensorConfig(time_constant_s=0.5, noise_std_mg_m3=0.0, sample_rate_hz=10.0)
    s = ChemicalSensor(cfg, seed=1)
    s.sample(0.0, 0.0)
    # Step to 10 mg/m^3 right after t = 0; read every 0.1 s.
    readings = [s.sample(0.1 * k, 10.0) for k in range(1, 11)]
    by_t = {round(r.t, 6): r.value_mg_m3 for r in readings}
    assert by_t[0.5] == pytest.approx(10.0 * (1.0 - math.exp(-1.0)), rel=1e-9)
    assert by_t[1.0] == pytest.approx(10.0 * (1.0 - math.exp(-2.0)), rel=1e-9)
    # Exact discretisation: the answer does not depend on the call spacing.
    s2 = ChemicalSensor(cfg, seed=1)
    s2.sample(0.0, 0.0)
    assert s2.sample(0.5, 10.0).value_mg_m3 == pytest.approx(by_t[0.5], rel=1e-12)


def test_saturation_clips_and_flags() -> None:
    cfg = ChemSensorConfig(time_constant_s=0.01, noise_std_mg_m3=0.0, saturation_mg_m3=100.0)
    s = ChemicalSensor(cfg, seed=1)
    r = _run(s, 5000.0, 20, 0.1)[-1]
    assert r.value_mg_m3 == 100.0
    assert r.saturated and r.detected
    r2 = _run(s, 50.0, 20, 0.1, t0=10.0)[-1]
    assert r2.value_mg_m3 == pytest.approx(50.0)
    assert not r2.saturated


def test_detection_limit_reports_zero_below() -> None:
    cfg = ChemSensorConfig(time_constant_s=0.01, noise_std_mg_m3=0.0, detection_limit_mg_m3=0.05)
    s = ChemicalSensor(cfg, seed=1)
    low = _run(s, 0.04, 10, 0.1)[-1]
    assert low.value_mg_m3 == 0.0 and not low.detected
    high = _run(s, 0.06, 10, 0.1, t0=5.0)[-1]
    assert high.detected and high.value_mg_m3 == pytest.approx(0.06)


def test_noise_std_matches_config() -> None:
    cfg = ChemSensorConfig(noise_std_mg_m3=0.2, detection_limit_mg_m3=0.0, time_constant_s=0.01)
    s = ChemicalSensor(cfg, seed=3)
    vals = np.array([r.value_mg_m3 for r in _run(s, 10.0, 20000, 0.1)])[100:]
    assert vals.mean() == pytest.approx(10.0, abs=0.01)
    assert vals.std() == pytest.approx(0.2, rel=0.03)


def test_clean_air_with_default_limit_gives_no_false_detections() -> None:
    s = ChemicalSensor(ChemSensorConfig(), seed=4)
    assert not any(r.detected for r in _run(s, 0.0, 5000, 0.1))


def test_seeded_readings_repeat_and_differ_between_seeds() -> None:
    cfg = ChemSensorConfig(noise_std_mg_m3=0.1)
    a = [r.value_mg_m3 for r in _run(ChemicalSensor(cfg, seed=7), 3.0, 50, 0.1)]
    b = [r.value_mg_m3 for r in _run(ChemicalSensor(cfg, seed=7), 3.0, 50, 0.1)]
    c = [r.value_mg_m3 for r in _run(ChemicalSensor(cfg, seed=8), 3.0, 50, 0.1)]
    assert a == b
    assert a != c


def test_validation_names_fields() -> None:
    errors = ChemSensorConfig(time_constant_s=0.0, saturation_mg_m3=0.01).validate()
    assert any(e.startswith("time_constant_s") for e in errors)
    assert any(e.startswith("saturation_mg_m3") for e in errors)
    with pytest.raises(ValueError, match="time_constant_s"):
        ChemicalSensor(ChemSensorConfig(time_constant_s=-1.0), seed=0)
    assert ChemSensorConfig().validate() == []


def test_time_must_not_decrease() -> None:
    s = ChemicalSensor(ChemSensorConfig(), seed=0)
    s.sample(1.0, 0.0)
    with pytest.raises(ValueError, match="decrease"):
        s.sample(0.5, 0.0)
