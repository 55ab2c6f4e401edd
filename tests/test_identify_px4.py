"""The identification flown on PX4 through MAVLink, without PX4: the setpoint law (identify/fly/px4_setpoint.py),
the record turned into flight data (px4_record.py), the safety checks (px4_guard.py), the typed parameters
and stream requests (px4_link.py) on stand-ins for MAVSDK's plugins, the vehicle's PX4 motor order, the
accelerometer noise a vehicle file carries into the estimator, and the command line's refusals."""

from __future__ import annotations

import asyncio
import json
import math
from typing import Any

import numpy as np
import pytest

from estimator.config import EstimatorConfig
from estimator.model_fit import ModelFit
from estimator.motor_output import PX4_QUAD_X, OutputMap, px4_order
from identify.design import ManoeuvreSpec, design
from identify.fly.px4_guard import Guard, GuardLimits
from identify.fly.px4_link import Params, link_loss_failsafe, request_streams
from identify.fly.px4_record import Recorder
from identify.fly.px4_setpoint import G, ManoeuvreLaw, fit_reference, tilt_for
from vehicle.frames import euler_to_quat, quat_to_dcm
from vehicle.vehicle_file import load_vehicle
from windseek.cli import main
from windseek.identify_connect import accel_noise

AMPS = (0.12, math.radians(5), math.radians(5), math.radians(10))


def _manoeuvre(duration: float = 30.0, speed: float = 3.0, climb: float = 1.0, seed: int = 0) -> Any:
    return design(ManoeuvreSpec(duration_s=duration, amplitudes=AMPS, speed_m_s=speed, climb_m_s=climb, seed=seed),
                  1.0)  # fmt: skip


# ---------------------------------------------------------------------------------------------- setpoints
@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.5])
@pytest.mark.parametrize("acc", [[2.0, 0.0, 0.0], [0.0, -1.5, 0.0], [1.0, 1.0, -2.0], [0.0, 0.0, 0.0]])
def test_tilt_for_points_the_thrust_along_the_wanted_force(acc: list[float], yaw: float) -> None:
    roll, pitch = tilt_for(np.array(acc), yaw)
    thrust_dir = quat_to_dcm(euler_to_quat(roll, pitch, yaw)) @ np.array([0.0, 0.0, -1.0])  # -z body in NED
    want = np.array(acc) - np.array([0.0, 0.0, G])
    assert np.allclose(thrust_dir, want / np.linalg.norm(want), atol=1e-9)


def test_fit_reference_keeps_the_path_inside_the_fence_and_climbs() -> None:
    m = _manoeuvre(duration=60.0, speed=3.0, climb=1.5)
    fit = fit_reference(m, fence_m=20.0, altitude_m=10.0, floor_m=3.0, ceiling_m=25.0, margin_m=2.0)
    t = np.arange(0.0, m.total_s, 0.25)
    path = np.array([fit.scale * m.position_reference(x) for x in t])
    assert np.abs(path[:, 0:2]).max() <= 18.0 + 1e-6  # fence - margin
    assert -path[:, 2].min() <= 25.0 - 2.0 - 10.0 + 1e-6 and path[:, 2].max() <= 10.0 - 3.0 - 2.0 + 1e-6
    assert -path[:, 2].min() > path[:, 2].max()  # the larger vertical excursion is a climb
    assert "scaled by" in fit.note
    roomy = fit_reference(m, fence_m=500.0, altitude_m=10.0, floor_m=3.0, ceiling_m=200.0)
    assert np.allclose(np.abs(roomy.scale), 1.0) and roomy.note.startswith("reference path inside")
    with pytest.raises(ValueError, match="room"):
        fit_reference(m, fence_m=50.0, altitude_m=10.0, floor_m=3.0, ceiling_m=12.0)


def test_manoeuvre_law_hover_errors_limits_and_excitation() -> None:
    m = _manoeuvre()
    fit = fit_reference(m, 150.0, 10.0, 3.0, 40.0)
    start = np.array([0.0, 0.0, -10.0])
    law = ManoeuvreLaw(m, start, 0.3, 0.5, fit)
    sp = law.setpoint(1.0, start, np.zeros(3))  # in the hover: no excitation, no reference
    assert abs(sp.roll_rad) < 1e-9 and abs(sp.pitch_rad) < 1e-9 and sp.yaw_rad == pytest.approx(0.3)
    assert sp.thrust == pytest.approx(0.5)
    north = ManoeuvreLaw(m, start, 0.0, 0.5, fit).setpoint(1.0, start - [3.0, 0.0, 0.0], np.zeros(3))
    assert north.pitch_rad < -0.05 and abs(north.roll_rad) < 1e-9  # behind the reference: nose down
    east = ManoeuvreLaw(m, start, 0.0, 0.5, fit).setpoint(1.0, start - [0.0, 3.0, 0.0], np.zeros(3))
    assert east.roll_rad > 0.05 and abs(east.pitch_rad) < 1e-9
    low = ManoeuvreLaw(m, start, 0.0, 0.5, fit).setpoint(1.0, start + [0.0, 0.0, 2.0], np.zeros(3))
    assert low.thrust > 0.55
    far = ManoeuvreLaw(m, start, 0.0, 0.5, fit).setpoint(1.0, start - [500.0, 500.0, 0.0], np.zeros(3))
    assert math.hypot(far.roll_rad, far.pitch_rad) <= math.radians(20.0) * 1.01  # the loop's tilt limit
    # in the manoeuvre, on the reference: the multisine itself (thrust fraction of hover, angles)
    law = ManoeuvreLaw(m, start, 0.0, 0.5, fit)
    tau = m.spec.hover_s + 7.3
    p_ref, v_ref, yaw_ref = law.reference(tau)
    sp = law.setpoint(tau, p_ref, v_ref)
    e = law.excitation(tau)
    assert abs(e[1]) <= AMPS[1] * 1.05 and abs(e[0]) <= AMPS[0] * 1.05 and np.any(np.abs(e) > 1e-3)
    assert sp.yaw_rad == pytest.approx(yaw_ref + e[3])
    with pytest.raises(ValueError, match="hover thrust"):
        ManoeuvreLaw(m, start, 0.0, 0.02, fit)


# ---------------------------------------------------------------------------------------------- the record
def _feed(rec: Recorder, t0: float, t1: float, u: Any = lambda t: [0.49, 0.49, 0.49, 0.49], sys_id: int = 1,
          skip: tuple[float, float] | None = None, imu: str = "HIGHRES_IMU") -> None:  # fmt: skip
    for k in range(int(round((t1 - t0) * 250))):
        t = t0 + k * 0.004
        if skip and skip[0] <= t < skip[1]:
            continue
        if imu == "HIGHRES_IMU":
            rec.sink("HIGHRES_IMU", {"time_usec": int(t * 1e6), "xacc": 0.1, "yacc": -0.2, "zacc": -9.8,
                                     "xgyro": 0.01, "ygyro": 0.0, "zgyro": 0.0}, t, sys_id, 1)  # fmt: skip
        else:
            rec.sink("SCALED_IMU", {"time_boot_ms": int(round(t * 1e3)), "xacc": 10, "yacc": -20, "zacc": -1000,
                                    "xgyro": 10, "ygyro": 0, "zgyro": 0}, t, sys_id, 1)  # fmt: skip
        if k % 2 == 0:
            q = euler_to_quat(0.0, 0.0, 0.1)
            rec.sink("ATTITUDE_QUATERNION", {"time_boot_ms": int(t * 1e3), "q1": q[0], "q2": q[1], "q3": q[2],
                                             "q4": q[3]}, t, sys_id, 1)  # fmt: skip
            rec.sink("ACTUATOR_OUTPUT_STATUS", {"time_usec": int(t * 1e6), "active": 4,
                                                "actuator": [1000.0 + 1000.0 * x for x in u(t)] + [0.0] * 28},
                     t, sys_id, 1)  # fmt: skip
        if k % 5 == 0:
            rec.sink("LOCAL_POSITION_NED", {"time_boot_ms": int(t * 1e3), "x": 1.0, "y": 2.0, "z": -10.0,
                                            "vx": 0.5, "vy": -0.25, "vz": 0.0}, t, sys_id, 1)  # fmt: skip


def test_record_to_flight_data_with_the_sih_motor_map() -> None:
    v = load_vehicle("px4-sih-quadx")
    rec = Recorder(OutputMap.for_vehicle(v, "px4", 0.0), v.n_rotors)
    rec.target = (1, 1)
    _feed(rec, 10.0, 30.0, u=lambda t: [0.49, 0.36, 0.64, 0.25])
    _feed(rec, 10.0, 12.0, sys_id=7)  # another system: ignored
    d = rec.flight_data(11.0, 29.0, "test")
    d.check(v.n_rotors)
    assert d.t[0] == pytest.approx(0.0) and d.duration_s == pytest.approx(18.0, abs=0.01)
    assert np.allclose(d.specific_force[0], [0.1, -0.2, -9.8]) and np.allclose(d.velocity_ned[5], [0.5, -0.25, 0.0])
    # SIH: thrust linear in the output, THR_MDL_FAC 0: rotor speed = 1000 sqrt(u), PX4's order = the file's
    assert np.allclose(d.rotor_speeds[10], [700.0, 600.0, 800.0, 500.0])
    assert np.allclose(d.rotor_commands, d.rotor_speeds) and d.excluded is None
    assert "ACTUATOR_OUTPUT_STATUS through the motor map" in d.source and rec.counts["HIGHRES_IMU"] == 5000
    assert rec.tilt_rad() == pytest.approx(0.0, abs=1e-9) and rec.outputs_u is not None


def test_record_paper_quad_order_saturation_gaps_and_refusals() -> None:
    v = load_vehicle("nasa-quad")
    rec = Recorder(OutputMap.for_vehicle(v, "px4", 0.0), v.n_rotors)
    rec.target = (1, 1)
    sat = (20.0, 20.3)
    _feed(rec, 10.0, 40.0, u=lambda t: [1.0 if sat[0] <= t < sat[1] else 0.5, 0.3, 0.4, 0.6], skip=(30.0, 31.0))
    d = rec.flight_data(10.0, 40.0, "test")
    w = d.rotor_speeds[0]  # PX4 outputs 1-4 = front-right, rear-left, front-left, rear-right -> rotors 1, 3, 4, 2
    speed = [math.sqrt(100.0**2 + x * (600.0**2 - 100.0**2)) for x in (0.5, 0.6, 0.3, 0.4)]
    assert np.allclose(w, speed)
    assert d.exclusions[0] == "motor output at its limit: 1.7 % of samples (9.9-10.4 s)"
    assert any(e.startswith("gap in HIGHRES_IMU") for e in d.exclusions[1:])
    bad = ~d.mask
    assert bad[(d.t > 9.9) & (d.t < 10.4)].all() and not bad[(d.t > 10.45) & (d.t < 19.9)].any()
    i = int(np.argmax(np.diff(d.t)))  # the IMU's own gap (20-21 s): its two edges, so resampling keeps it out
    assert d.t[i + 1] - d.t[i] > 0.9 and bad[i] and bad[i + 1]
    r2 = Recorder(OutputMap.for_vehicle(v, "px4"), 4)
    for t in (1.0, 1.004):
        r2.sink("HIGHRES_IMU", {"time_usec": int(t * 1e6), "xacc": 0, "yacc": 0, "zacc": 0, "xgyro": 0, "ygyro": 0,
                                "zgyro": 0}, t, 1, 1)  # fmt: skip
    with pytest.raises(ValueError, match=r"^no attitude, velocity \(LOCAL_POSITION_NED\), motor outputs"):
        r2.flight_data(0.0, 20.0, "x")


def test_record_scaled_imu_and_esc_telemetry_only_when_asked_for() -> None:
    v = load_vehicle("px4-sih-quadx")
    rec = Recorder(OutputMap.for_vehicle(v, "px4", 0.0), 4, esc_component=None, imu="SCALED_IMU")
    rec.target = (1, 1)
    _feed(rec, 0.0, 12.0, imu="SCALED_IMU")
    rec.sink("ESC_STATUS", {"time_usec": 5_000_000, "index": 0, "rpm": [6000, 6000, 6000, 6000]}, 5.0, 1, 1)
    assert rec.ignored_esc == 1 and rec.counts["ESC_STATUS"] == 0  # PX4 SITL's placeholder: not used
    for _ in range(2):  # a repeated time stamp (PX4 resends a sample): kept once, never compared by value
        rec.sink("ATTITUDE_QUATERNION", {"time_boot_ms": 6000, "q1": 1.0, "q2": 0.0, "q3": 0.0, "q4": 0.0}, 6.0, 1, 1)
    d = rec.flight_data(0.5, 11.5, "test")
    assert np.allclose(d.specific_force[3], [0.0980665, -0.196133, -9.80665]) and d.rates[3, 0] == pytest.approx(0.01)
    assert "IMU SCALED_IMU" in d.source
    with pytest.raises(ValueError, match="IMU message"):
        Recorder(OutputMap.for_vehicle(v, "px4"), 4, imu="RAW_IMU")


def test_esc_telemetry_numbered_by_px4_outputs_or_by_rotors() -> None:
    """ESC i is PX4 output i on a real vehicle (``px4``); windseek's component 158 numbers them as its rotors
    (``rotors``): the paper's quad X, whose PX4 outputs 1-4 are rotors 1, 3, 4, 2."""
    v = load_vehicle("nasa-quad")
    rpm = [1000.0, 2000.0, 3000.0, 4000.0]
    speeds = {}
    for order in ("px4", "rotors"):
        rec = Recorder(OutputMap.for_vehicle(v, "px4", 1.0), 4, esc_component=158, esc_order=order)
        rec.target = (1, 1)
        _feed(rec, 0.0, 6.0)
        for k in range(0, 300):
            rec.sink("ESC_STATUS", {"time_usec": k * 20_000, "index": 0, "rpm": rpm}, k * 0.02, 1, 158)
        d = rec.flight_data(0.5, 5.5, "test")
        speeds[order] = d.rotor_speeds[100] * 60.0 / (2.0 * math.pi)
        assert f"ESC_STATUS of component 158 (ESC order {order})" in d.source
    assert np.allclose(speeds["rotors"], rpm)
    assert np.allclose(speeds["px4"], [rpm[0], rpm[3], rpm[1], rpm[2]])  # rotor r = output k with PX4_QUAD_X[k] = r
    with pytest.raises(ValueError, match="ESC order"):
        Recorder(OutputMap.for_vehicle(v, "px4"), 4, esc_order="sitl")


def test_accel_noise_of_a_record_recovers_white_noise() -> None:
    v = load_vehicle("px4-sih-quadx")
    rec = Recorder(OutputMap.for_vehicle(v, "px4", 0.0), 4)
    rec.target = (1, 1)
    _feed(rec, 0.0, 30.0)
    d = rec.flight_data(0.5, 29.5, "test")
    rng = np.random.default_rng(3)
    noisy = type(d)(t=d.t, specific_force=d.specific_force + rng.normal(0.0, [0.3, 1.2, 1.0], d.specific_force.shape),
                    rates=d.rates, rotor_speeds=d.rotor_speeds, velocity_ned=d.velocity_ned, quaternion=d.quaternion)
    assert np.allclose(accel_noise(noisy), [0.3, 1.2, 1.0], rtol=0.05)


# ---------------------------------------------------------------------------------------------- safety
def test_guard_fence_floor_tilt_and_saturation() -> None:
    home = np.array([0.0, 0.0, 0.0])
    g = Guard(GuardLimits(fence_m=50.0, floor_m=3.0, ceiling_m=30.0, tilt_deg=35.0, saturation_s=0.5), home)
    assert g.position(np.array([40.0, -45.0, -10.0]), True) is None
    a = g.position(np.array([53.0, 0.0, -10.0]), True)
    assert a is not None and a.cause == "geofence"
    a = g.position(np.array([0.0, 0.0, -33.0]), True)
    assert a is not None and a.cause == "geofence"
    assert g.position(np.array([0.0, 0.0, -0.5]), False) is None  # take-off / landing: no floor
    a = g.position(np.array([0.0, 0.0, -0.5]), True)
    assert a is not None and a.cause == "floor"
    assert g.attitude(math.radians(30.0)) is None and g.attitude(None) is None
    a = g.attitude(math.radians(36.0))
    assert a is not None and a.cause == "attitude" and "36.0 deg" in a.line()
    u_ok, u_sat = np.array([0.5, 0.5, 0.5, 0.5]), np.array([0.5, 1.0, 0.5, 0.5])
    assert g.outputs(10.0, u_sat) is None and g.outputs(10.4, u_sat) is None
    assert g.outputs(10.45, u_ok) is None and g.outputs(10.5, u_sat) is None  # the run starts again
    assert g.outputs(10.99, u_sat) is None
    a = g.outputs(11.05, u_sat)
    assert a is not None and a.cause == "saturation" and "output 2 at 1" in a.message
    with pytest.raises(ValueError, match="floor"):
        GuardLimits(floor_m=30.0, ceiling_m=20.0).validate()


# ---------------------------------------------------------------------------------------------- parameters
class FakeParams:
    """MAVSDK's param plugin as PX4 answers it: INT32 and REAL32 parameters, a set of the wrong type refused."""

    def __init__(self, values: dict[str, tuple[str, float]]) -> None:
        self.values = dict(values)
        self.sets: list[tuple[str, float]] = []

    async def _get(self, name: str, kind: str) -> float:
        if name not in self.values or self.values[name][0] != kind:
            raise RuntimeError("WRONG_TYPE" if name in self.values else "NOT_FOUND")
        return self.values[name][1]

    async def get_param_int(self, name: str) -> int:
        return int(await self._get(name, "int"))

    async def get_param_float(self, name: str) -> float:
        return float(await self._get(name, "float"))

    async def set_param_int(self, name: str, value: int) -> None:
        await self._get(name, "int")
        self.values[name] = ("int", float(value))
        self.sets.append((name, value))

    async def set_param_float(self, name: str, value: float) -> None:
        await self._get(name, "float")
        self.values[name] = ("float", value)
        self.sets.append((name, value))


def test_failsafes_set_with_their_px4_types_and_read_back() -> None:
    fake = FakeParams({"NAV_DLL_ACT": ("int", 0), "COM_DL_LOSS_T": ("int", 10), "COM_OBL_RC_ACT": ("int", 0),
                       "COM_OF_LOSS_T": ("float", 1.0)})  # fmt: skip
    now, before, problems = asyncio.run(link_loss_failsafe(Params(fake), 4.0, 5.0, 1.0))
    assert problems == [] and before["NAV_DLL_ACT"] == 0.0
    assert now == {"NAV_DLL_ACT": 3.0, "COM_DL_LOSS_T": 20.0, "COM_OBL_RC_ACT": 5.0, "COM_OF_LOSS_T": 4.0}
    assert fake.values["COM_OF_LOSS_T"] == ("float", 4.0) and fake.values["COM_DL_LOSS_T"] == ("int", 20.0)
    kept = FakeParams({"NAV_DLL_ACT": ("int", 2), "COM_DL_LOSS_T": ("int", 5), "COM_OBL_RC_ACT": ("int", 5),
                       "COM_OF_LOSS_T": ("float", 1.0)})  # fmt: skip
    now, _, problems = asyncio.run(link_loss_failsafe(Params(kept), 1.0, 5.0, 1.0))
    assert now["NAV_DLL_ACT"] == 2.0 and kept.sets == [] and problems == []  # return mode kept; nothing written
    missing = FakeParams({"COM_OF_LOSS_T": ("float", 1.0)})
    now, _, problems = asyncio.run(link_loss_failsafe(Params(missing), 1.0, 5.0, 1.0))
    assert "NAV_DLL_ACT" not in now and any(p.startswith("NAV_DLL_ACT") for p in problems)


def test_params_set_refuses_what_does_not_read_back() -> None:
    class Stuck(FakeParams):
        async def set_param_float(self, name: str, value: float) -> None:
            self.sets.append((name, value))  # accepted, never applied

    p = Params(Stuck({"MIS_TAKEOFF_ALT": ("float", 2.5)}))
    with pytest.raises(RuntimeError, match="read back 2.5"):
        asyncio.run(p.set("MIS_TAKEOFF_ALT", 10.0))
    with pytest.raises(RuntimeError, match="no such parameter"):
        asyncio.run(p.set("NOPE", 1.0))


def test_stream_requests_are_command_long_511_with_the_interval() -> None:
    sent: list[dict[str, Any]] = []

    class Direct:
        async def send_command(self, msg: Any) -> Any:
            f = json.loads(msg.fields_json)
            sent.append(f)
            res = 3 if f["param1"] == 291.0 else 0

            class Ack:
                fields_json = json.dumps({"result": res})

            return Ack()

    out = asyncio.run(request_streams(Direct(), (5, 1), {"HIGHRES_IMU": 250.0, "ESC_STATUS": 50.0}))
    assert out == {"HIGHRES_IMU": "accepted", "ESC_STATUS": "unsupported"}
    assert sent[0]["command"] == 511 and sent[0]["param1"] == 105.0 and sent[0]["param2"] == pytest.approx(4000.0)
    assert sent[0]["target_system"] == 5


# ---------------------------------------------------------------------------------------------- plumbing
def test_px4_output_order_comes_from_the_vehicle_file() -> None:
    assert px4_order(load_vehicle("nasa-quad")) == PX4_QUAD_X
    assert px4_order(load_vehicle("px4-sih-quadx")) == (0, 1, 2, 3)  # listed in PX4's own order
    assert OutputMap.for_vehicle(load_vehicle("px4-sih-quadx"), "px4").order == (0, 1, 2, 3)
    assert px4_order(load_vehicle("hexa-550")) == tuple(range(6))


def test_a_measured_accelerometer_noise_widens_the_estimators_noise() -> None:
    from dataclasses import replace

    v = load_vehicle("px4-sih-quadx")
    base = EstimatorConfig.for_vehicle(v).accel_noise_m_s2
    noisy = replace(v, model_info={**v.model_info, "accel_noise_m_s2": [0.3, 1.2, 1.0]})
    got = EstimatorConfig.for_vehicle(noisy).accel_noise_m_s2
    assert got == pytest.approx([math.hypot(b, n) for b, n in zip(base, (0.3, 1.2, 1.0), strict=True)])
    assert EstimatorConfig.for_vehicle(noisy, accel_noise_m_s2=(1.0, 1.0, 1.0)).accel_noise_m_s2 == (1.0, 1.0, 1.0)


def test_model_fit_says_when_it_found_the_mismatch() -> None:
    fit = ModelFit(load_vehicle("nasa-quad"))
    t = 0.0
    for _ in range(2000):  # a 1 kg vehicle's hover on the 2.8 kg model's rotor speeds: thrust mismatch
        fit.sample(t, np.array([0.0, 0.0, -9.8]), np.zeros(3), np.full(4, 240.0), True, None, False)
        t += 0.004
    assert fit.mismatch is not None and fit.mismatch_t_s is not None and 3.9 < fit.mismatch_t_s < 4.5
    assert fit.summary()["mismatch_t_s"] == pytest.approx(fit.mismatch_t_s, abs=1e-3)


def test_identify_connect_refusals(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", "--connect", "udpin://0.0.0.0:14540"]) == 2
    assert "needs --vehicle" in capsys.readouterr().err
    assert main(["identify", "calm", "--connect", "udpin://0.0.0.0:14540", "--vehicle", "px4-sih-quadx"]) == 2
    assert "not both" in capsys.readouterr().err
    assert main(["identify", "--connect", "udpin://0.0.0.0:14540", "--vehicle", "px4-sih-quadx",
                 "--setpoint-amplitudes", "0.12,5,5"]) == 2  # fmt: skip
    assert "T,R,P,Y" in capsys.readouterr().err
    assert main(["identify", "--connect", "udpin://0.0.0.0:14540", "--vehicle", "px4-sih-quadx", "--floor", "30",
                 "--ceiling", "20"]) == 2  # fmt: skip
    assert "floor" in capsys.readouterr().err
    assert main(["identify", "--connect", "udpin://0.0.0.0:14540", "--vehicle", "nasa-quad", "--max-clock-speed",
                 "-1"]) == 2  # fmt: skip
    assert "--max-clock-speed -1" in capsys.readouterr().err


def test_take_off_command_carries_home_altitude_plus_the_wanted_height() -> None:
    from mission.runners.takeoff import takeoff_above_home

    sent: list[dict[str, Any]] = []

    class Direct:
        result = 0

        async def send_command(self, msg: Any) -> Any:
            sent.append(json.loads(msg.fields_json))

            class Ack:
                fields_json = json.dumps({"result": Direct.result})

            return Ack()

    class V:
        home: dict[str, Any] | None = {"altitude": 488_000}
        target = (3, 1)
        direct = Direct()

    assert asyncio.run(takeoff_above_home(V(), 10.0)) is None  # type: ignore[arg-type]
    f = sent[0]
    assert f["command"] == 22 and f["param7"] == pytest.approx(498.0) and f["target_system"] == 3
    assert f["param5"] is None and f["param6"] is None  # NaN on the wire: take off where it stands
    Direct.result = 4
    assert "refused (MAV_RESULT 4)" in str(asyncio.run(takeoff_above_home(V(), 10.0)))  # type: ignore[arg-type]
    V.home = None
    assert "no HOME_POSITION" in str(asyncio.run(takeoff_above_home(V(), 10.0, timeout_s=0.2)))  # type: ignore[arg-type]
