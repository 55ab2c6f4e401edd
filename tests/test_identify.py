"""The system identification end to end in-process: data the model structure itself generated are recovered
to the noise; `windseek identify` writes a vehicle file every program loads; bad flight data and unexcited
axes are said, never fitted."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from estimator.config import preset_for
from identify.design import ManoeuvreSpec, design
from identify.flight_data import FlightData
from identify.fly.world import fly
from identify.pipeline import identify
from identify.report import identified_vehicle
from sitl.scenario import Scenario, load_scenario
from vehicle.params import VehicleParams
from vehicle.rotor_model import wrench
from vehicle.vehicle_file import load_vehicle

ROOT = Path(__file__).resolve().parent.parent


def _calm(vehicle: str, turbulence: bool = True) -> Scenario:
    sc = replace(load_scenario("calm"), vehicle=vehicle)
    return sc if turbulence else replace(sc, turbulence=None)


@pytest.fixture(scope="module")
def model_world() -> tuple[VehicleParams, FlightData, FlightData]:
    """nasa-quad's identified Eq. 46 as the world's truth, no turbulence: a fitting and a validation flight."""
    truth = replace(load_vehicle("nasa-quad"), truth="model")
    hd = truth.n_rotors * truth.control["hover_speed"] ** 2
    sc = _calm("nasa-quad", turbulence=False)
    fd = fly(sc, 11, design(ManoeuvreSpec(duration_s=60.0), hd), truth)
    vd = fly(sc, 12, design(ManoeuvreSpec(duration_s=30.0, seed=1), hd), truth)
    return truth, fd, vd


def test_data_from_the_model_structure_itself_are_recovered_to_the_noise(
    model_world: tuple[VehicleParams, FlightData, FlightData],
) -> None:
    """The world flies the identified Eq. 46 of nasa-quad (truth = "model"), no turbulence: the identification
    explains the forces to the sensors' noise and finds the same force *function* back over the domain it
    flew; the well-conditioned terms (thrust, the rotors' H-force) each within their 95 % interval (widened
    by 3 %). Individual drag terms are not compared: u|u| and u v0 are near-collinear over a 4 m/s domain,
    and the stepwise fit may trade one for the other at no cost to the forces."""
    truth, fd, vd = model_world
    # The truth's own saturation of the airspeed regressors, or the coefficients would absorb the difference.
    res = identify(fd, truth, vd, domain_m_s=(truth.domain_airspeed_m_s, truth.domain_vertical_airspeed_m_s))
    for axis in ("x", "y", "z"):
        assert res.axes[axis].r2_pct > 99.7, (axis, res.axes[axis].r2_pct)
        val_tic = res.axes[axis].val_tic
        assert val_tic is not None and val_tic < 0.02, axis
    for name in ("C_X_Hmu", "C_Y_Hmu", "C_Z_T0", "C_Z_Tz"):
        th, ci, true = res.coefficients[name], res.ci95[name], truth.coefficients[name]
        assert abs(th - true) <= 2.0 * ci + 0.03 * abs(th), (name, th, true, ci)
    found = identified_vehicle(truth, res)
    w_hover = np.full(4, truth.control["hover_speed"])
    lo, hi = (np.array([res.domain[k][i] for k in ("u", "v", "w")]) for i in (0, 1))
    grid = [np.array([u, v, w]) for u in np.linspace(lo[0], hi[0], 5) for v in np.linspace(lo[1], hi[1], 5)
            for w in np.linspace(lo[2], hi[2], 3)]  # fmt: skip
    f_true = np.array([wrench(truth, va, np.zeros(3), w_hover)[:3] for va in grid])
    f_found = np.array([wrench(found, va, np.zeros(3), w_hover)[:3] for va in grid])
    err = np.abs(f_found - f_true).max(axis=0)
    weight = truth.mass_kg * 9.80665
    assert err[0] < 0.01 * weight and err[1] < 0.01 * weight and err[2] < 0.01 * weight, err / weight


def test_an_accelerometer_offset_is_the_flights_bias_not_the_vehicles(
    model_world: tuple[VehicleParams, FlightData, FlightData],
) -> None:
    """0.05 m/s^2 more on the fitting flight's x accelerometer and -0.03 on y: the fitted X and Y biases
    take m times that, the drag terms do not move (an unmodelled offset used to bend them by as much)."""
    truth, fd, vd = model_world
    dom = (truth.domain_airspeed_m_s, truth.domain_vertical_airspeed_m_s)
    base = identify(fd, truth, vd, domain_m_s=dom)
    shifted = identify(replace(fd, specific_force=fd.specific_force + [0.05, -0.03, 0.0]), truth, vd, domain_m_s=dom)
    for axis, offset in (("x", 0.05), ("y", -0.03)):
        b0, b1 = base.axes[axis].bias, shifted.axes[axis].bias
        assert b0 is not None and b1 is not None
        assert b1[0] - b0[0] == pytest.approx(truth.mass_kg * offset, rel=0.02), axis
        assert base.axes[axis].names == shifted.axes[axis].names
        for th0, th1, ci in zip(base.axes[axis].theta, shifted.axes[axis].theta, base.axes[axis].ci95, strict=True):
            assert abs(th1 - th0) < 0.05 * ci, (axis, th0, th1, ci)
        # The validation flight carries its own bias: its metrics do not see the fitting flight's.
        assert shifted.axes[axis].val_tic == pytest.approx(base.axes[axis].val_tic, rel=1e-6)
    assert base.axes["z"].bias is None and base.axes["l"].bias is None


def test_windseek_identify_writes_a_vehicle_file_the_estimator_uses(tmp_path: Path) -> None:
    out = tmp_path / "my.toml"
    res = subprocess.run([sys.executable, "-m", "windseek.cli", "identify", "calm", "--seed", "3", "--duration", "40",
                          "--validation-duration", "20", "-o", str(out), "--json"],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    d = json.loads(res.stdout)
    assert d["truth"] == "bet" and set(d["axes"]) == {"x", "y", "z", "l", "m", "n"}
    for m in d["axes"].values():
        assert {"r2_pct", "s2", "fit_tic", "fit_nrmse", "val_tic", "val_nrmse"} <= set(m)
    assert d["axes"]["x"]["r2_pct"] > 99.0 and d["axes"]["z"]["val_tic"] < 0.02
    v = load_vehicle(out)
    assert v.truth == "bet" and v.name == "nasa-quad" and preset_for(v) == "calibrated"
    assert v.model_info["source"] == "windseek identify calm --seed 3" and "domain_p5_p95" in v.model_info
    assert set(v.coefficients) == set(d["coefficients"]) and all(v.ci95[k] > 0 for k in v.coefficients)
    est = subprocess.run([sys.executable, "-m", "windseek.cli", "estimate", "paper-s1", "--duration", "15",
                          "--vehicle", str(out), "--json"],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)  # fmt: skip
    e = json.loads(est.stdout)
    assert e["estimator_model"].endswith("windseek identify calm --seed 3") and e["calibration"] == "calibrated"
    assert e["rmse_horizontal_avg_ms"] < 1.0  # a 40 s identification still holds a 10 m/s wind


def _hover(n: int = 3000) -> FlightData:
    """12 s of a steady hover at 250 Hz with seeded sensor noise (accelerometer 0.05 m/s^2,
    gyroscope 3 mrad/s, rotor speed 1 rad/s)."""
    rng = np.random.default_rng(5)
    t = np.arange(n) * 0.004
    w = 393.0 + rng.normal(0.0, 1.0, (n, 4))
    acc = np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 0.05, (n, 3))
    return FlightData(t=t, specific_force=acc, rates=rng.normal(0.0, 0.003, (n, 3)), rotor_speeds=w,
                      velocity_ned=np.zeros((n, 3)), quaternion=np.tile([1.0, 0, 0, 0], (n, 1)),
                      source="a test hover")  # fmt: skip


@pytest.mark.parametrize(("change", "says"), [
    ({"rotor_speeds": np.zeros((0, 4))}, "lacks rotor_speeds"),
    ({"quaternion": np.zeros((0, 4))}, "lacks quaternion"),
    ({"t": np.arange(3000) * 0.001}, "at least 10 s of flight"),
    ({"rates": np.full((3000, 3), np.nan)}, "rates (gyroscope) has NaN"),
])  # fmt: skip
def test_bad_flight_data_is_one_line_naming_what_is_missing(change: dict, says: str) -> None:
    fd = replace(_hover(), **change)
    with pytest.raises(ValueError, match="flight data") as e:
        identify(fd, load_vehicle("nasa-quad"))
    assert says in str(e.value) and "\n" not in str(e.value)


def test_a_hover_excites_nothing_and_says_so() -> None:
    """A steady hover: no airspeed, no rates, equal rotors: every drag, moment and rate term is not excited
    and none is fitted; only the thrust's zero-airspeed term is."""
    res = identify(_hover(), load_vehicle("nasa-quad"))
    assert "C_X_Hmu" in res.axes["x"].not_identified and res.axes["x"].names == ()
    assert "C_l_p_dt" in res.axes["l"].not_identified and res.axes["l"].names == ()
    assert "C_Z_T0" in res.axes["z"].names or "C_Z_Tv" in res.axes["z"].names
