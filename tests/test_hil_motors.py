"""PX4's outputs to windseek's rotors: motor order and spin against the rotor model and the shipped
parameter file, the thrust curve against PX4's THR_MDL_FAC model, the checks of an output set, and
the PX4 SITL environment."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hil_support import hover_output, place_in_air, scenario

from estimator.mavlink_adapter import PX4_QUAD_X
from sitl.hil.bridge import HilBridge
from sitl.hil.motors import PX4_TO_ROTOR, MotorMap, px4_figures
from sitl.hil.px4_params import PARAMS_DIR, PARAMS_FILE, format_params_file, px4_env, read_params_file, vehicle_params
from vehicle.truth import static_thrust, static_wrench
from vehicle.vehicle_file import load_vehicle

VEHICLE = load_vehicle("nasa_quad")


def _params() -> dict[str, float]:
    return {p.name: p.value for p in read_params_file()}


@pytest.mark.parametrize("name", ["nasa_quad", "quad_340", "hexa_550"])
def test_every_shipped_parameter_file_is_its_vehicle_files(name: str) -> None:
    """``sitl/px4/windseek_<vehicle>.params`` is what px4_params writes from the vehicle file (regenerate it with
    ``python -m sitl.hil.px4_params --write ... --vehicle <vehicle>`` when the vehicle changes)."""
    v = load_vehicle(name)
    assert (PARAMS_DIR / f"windseek_{name}.params").read_text() == format_params_file(vehicle_params(v), v)
    p = {q.name: q.value for q in read_params_file(PARAMS_DIR / f"windseek_{name}.params")}
    assert p["CA_ROTOR_COUNT"] == v.n_rotors
    assert [p[f"PWM_MAIN_FUNC{i}"] for i in range(1, v.n_rotors + 1)] == [100 + i for i in range(1, v.n_rotors + 1)]


def test_shipped_parameter_file_is_the_vehicle_files() -> None:
    """The paper's vehicle's file: its figures."""
    assert PARAMS_FILE.read_text() == format_params_file(vehicle_params(VEHICLE), VEHICLE)
    p = _params()
    assert p["CA_ROTOR_COUNT"] == 4 and p["CA_AIRFRAME"] == 0
    assert p["MPC_THR_HOVER"] == pytest.approx(0.429, abs=2e-3)
    assert 0.9 < p["THR_MDL_FAC"] <= 1.0  # blade-element static thrust: nearly quadratic in the rotor speed
    assert p["CA_ROTOR0_KM"] == pytest.approx(0.0183, abs=1e-3)  # a 14-in propeller's torque / thrust
    assert [p[f"PWM_MAIN_FUNC{i}"] for i in range(1, 5)] == [101, 102, 103, 104]
    assert [p[f"HIL_ACT_FUNC{i}"] for i in range(1, 5)] == [101, 102, 103, 104]
    # Arm 0.2036 m (vehicle file) in an X: 0.144 m along both body axes.
    assert abs(p["CA_ROTOR0_PX"]) == pytest.approx(0.2036 / math.sqrt(2), abs=1e-3)


def test_each_px4_motor_moves_the_world_as_the_parameter_file_says() -> None:
    """More thrust on PX4 motor i (alone) gives roll -PY_i, pitch +PX_i, yaw sign KM_i (PX4's effectiveness,
    ActuatorEffectivenessRotors) in windseek's world (the vehicle's blade-element truth)."""
    p = _params()
    w0 = VEHICLE.control["hover_speed"]
    base = static_wrench(VEHICLE, np.full(4, w0))
    mm = MotorMap(VEHICLE)
    for i in range(4):
        out = np.full(4, w0 / mm.omega_max)
        out[i] += 0.05
        d = static_wrench(VEHICLE, mm.speeds(out)) - base
        assert d[2] < 0  # more thrust (up = -z)
        assert np.sign(d[3]) == -np.sign(p[f"CA_ROTOR{i}_PY"]), f"roll of motor {i + 1}"
        assert np.sign(d[4]) == np.sign(p[f"CA_ROTOR{i}_PX"]), f"pitch of motor {i + 1}"
        assert np.sign(d[5]) == np.sign(p[f"CA_ROTOR{i}_KM"]), f"yaw of motor {i + 1}"
    assert PX4_TO_ROTOR == PX4_QUAD_X  # the estimator's quad-X ESC order is the same map


def test_thrust_curve_is_px4s_thrust_model() -> None:
    """thrust(u) / thrust(1) = f u^2 + (1 - f) u with f = THR_MDL_FAC, and the hover output gives MPC_THR_HOVER."""
    f = px4_figures(VEHICLE)
    mm = MotorMap(VEHICLE)

    def thrust(u: float) -> float:  # the truth's (blade-element) static thrust of the four rotors
        return 4.0 * static_thrust(VEHICLE, float(mm.speeds(np.full(4, u))[0]))

    t1 = thrust(1.0)
    for u in (0.3, 0.5, 0.655, 0.9):  # THR_MDL_FAC is a two-term fit of the blade-element curve
        assert thrust(u) / t1 == pytest.approx(f.thr_mdl_fac * u * u + (1 - f.thr_mdl_fac) * u, rel=0.01)
    u_hover = VEHICLE.control["hover_speed"] / mm.omega_max
    assert thrust(u_hover) == pytest.approx(VEHICLE.mass_kg * VEHICLE.gravity_m_s2, rel=1e-6)  # 4 rotors
    assert thrust(u_hover) / t1 == pytest.approx(f.hover_thrust, rel=0.01)
    assert 2.0 < f.thrust_to_weight < 2.6


def test_output_checks() -> None:
    mm = MotorMap(VEHICLE)
    ok = mm.check([0.5, 0.1, 0.2, 0.3] + [0.0] * 12, 129)
    assert ok.problem == "" and ok.armed
    assert ok.speeds == pytest.approx([300.0, 180.0, 60.0, 120.0])  # FR, RR (out 4), RL (out 2), FL (out 3)
    assert mm.outputs(ok.speeds) == pytest.approx([0.5, 0.1, 0.2, 0.3])
    off = mm.check([0.0] * 16, 1)
    assert not off.armed and off.speeds == pytest.approx([0.0] * 4)
    cases = {
        "non_finite": [math.nan, 0.5, 0.5, 0.5] + [0.0] * 12,
        "out_of_range": [1.2, 0.5, 0.5, 0.5] + [0.0] * 12,
        "wrong_airframe": [0.5] * 6 + [0.0] * 10,
        "bad_length": [0.5] * 8,
    }
    for problem, controls in cases.items():
        v = mm.check(controls, 129)
        assert v.speeds is None and v.problem == problem, (problem, v)
        assert v.why
    assert mm.check([0.5, 0.5, 0.5, -0.5] + [0.0] * 12, 129).problem == "out_of_range"
    assert mm.check([0.5, 0.5, 0.5, math.inf] + [0.0] * 12, 1).problem == "non_finite"
    # The finite test is one sum: finite values whose sum overflows are not taken for NaN or infinity.
    assert mm.check([1e308, 1e308, 0.5, 0.5] + [0.0] * 12, 129).problem == "out_of_range"
    assert mm.check([0.5] * 4 + [0.0] * 11 + [-math.inf], 129).problem == "non_finite"


def test_px4_env_for_sitl() -> None:
    env = px4_env(speed=5.0, logging=False)
    assert env["PX4_SYS_AUTOSTART"] == "10016" and env["PX4_SIM_MODEL"] == "none_iris"
    assert env["PX4_PARAM_THR_MDL_FAC"] == "1" and env["PX4_PARAM_CA_ROTOR1_KM"] == "0.0183"
    assert env["PX4_PARAM_COM_DL_LOSS_T"] == "50" and env["PX4_PARAM_COM_OF_LOSS_T"] == "5"
    assert env["PX4_PARAM_SDLOG_BACKEND"] == "0"
    assert not any(k.startswith("PX4_PARAM_HIL_ACT") for k in env)  # not parameters of a SITL build
    assert px4_env(speed=0.5)["PX4_PARAM_COM_DL_LOSS_T"] == "10"  # never below PX4's defaults


def test_motor_mapping_in_the_world() -> None:
    """Through the bridge: a stronger front-right motor (PX4 1, CCW) rolls left, pitches up, yaws right;
    a stronger front-left one (PX4 3, CW) rolls right, pitches up, yaws left."""
    for motor, signs in ((0, (-1, 1, 1)), (2, (1, 1, -1))):
        b = HilBridge(scenario(), say=lambda s: None)
        place_in_air(b, 10.0)
        out = [hover_output(b)] * 4 + [0.0] * 12
        out[motor] += 0.03
        assert b.on_controls(out, 129)
        for _ in range(25):  # 0.1 s
            b.step()
        rates = b.world.rates
        assert tuple(np.sign(rates)) == signs, (motor, rates)


def test_the_readme_shell_line_exports_the_environment() -> None:
    """``eval "$(python -m sitl.hil.px4_params --speed 10 --no-log)"`` in sh gives PX4 exactly px4_env()."""
    import os
    import subprocess
    import sys

    script = f'PX4_SIMULATOR=sihsim; export PX4_SIMULATOR; eval "$("{sys.executable}" -m sitl.hil.px4_params ' \
             '--speed 10 --no-log)"; env'  # fmt: skip
    out = subprocess.run(["sh", "-c", script], capture_output=True, text=True, check=True, timeout=120,
                         cwd=os.path.dirname(os.path.dirname(__file__))).stdout  # fmt: skip
    got = dict(line.split("=", 1) for line in out.splitlines() if line.startswith("PX4_"))
    assert got == px4_env(10.0, logging=False)  # and PX4_SIMULATOR is unset (else PX4 would pick SIH)
