"""Wind estimator: convergence, step tracking, coverage, input rejection, gaps, MAVLink decoding.

Short scenarios keep the whole file to a few tens of seconds on two cores.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from estimator.direction import DirectionFilter, angle_diff_deg, from_direction_deg, speed_direction
from estimator.mavlink_adapter import MavlinkWindAdapter
from estimator.metrics import accuracy, moving_average, reconvergence_time
from estimator.rpm_free import MotorCommandModel
from estimator.ukf import PRESETS, EstimatorConfig, WindEstimator
from mission.runners.estimator_run import InProcessRunner
from sitl.scenario import load_scenario
from sitl.world.wind import SteadyWind, WindChange
from vehicle.frames import euler_to_quat
from vehicle.rotor_model import hover_rotor_speed
from vehicle.vehicle_file import load_vehicle
from wire.dialect import mavlink


def _steady(wind, duration, changes=()):
    sc = load_scenario("paper-s1")
    return replace(
        sc, duration_s=duration, turbulence=None, wind=SteadyWind(velocity_ned=wind, changes=tuple(changes))
    )


#: The paper's vehicle flying its own Table 5 model (truth = "model"): where a test is about the filter's
#: mechanics with an exact model, not about how well a model fits a vehicle (benchmarks/wind_accuracy.py).
EXACT = "nasa-quad-table5"


# ------------------------------------------------------------------ filter behaviour in the loop
def test_cold_start_converges_on_constant_wind():
    runner = InProcessRunner(_steady((-6.0, 3.0, 0.0), 8.0), seed=2)
    e0 = runner.estimator.estimate(advance_direction=False)
    assert np.all(e0.wind_ned == 0.0) and e0.sigma_ned.min() >= 10.0, "starts from no prior (zero wind, 10 m/s)"
    log = runner.run()
    # The first sample updates, but cannot tell the wind from the unknown ground velocity (2 m/s prior).
    assert log.wind_sigma[0, :2].min() > 0.8
    late = log.t > 4.0
    err = log.wind_est[late] - log.wind_true[late]
    # 0.5: the blade-element world against the identified model, whose steady drag at 5-7 m/s is
    # ~0.03 m/s^2 short of the truth's (0.3 m/s of wind at this airspeed: benchmarks/README.md,
    # "Identification"), and the force scale takes part of the cold-start transient (released ~1.5 s
    # after the start, EstimatorConfig.scale_hold_s).
    assert np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)) < 0.5
    assert np.all(log.wind_sigma[late, :2] < 0.5)
    d = from_direction_deg(log.wind_est[late, 0], log.wind_est[late, 1])
    assert np.sqrt(np.mean(angle_diff_deg(d, from_direction_deg(-6.0, 3.0)) ** 2)) < 4.5  # 0.5 m/s at 6.7 m/s


def test_tracks_a_wind_step():
    # The re-convergence time of one seed is noisy (seeds 3-7: 1.7-3.1 s, filterpy-era code
    # 2.5-4.6 s), so the goal (<= 3 s, as in benchmarks/README.md) is checked on the mean of three.
    sc = _steady((-8.0, 0.0, 0.0), 11.0, [WindChange(5.0, (-4.0, -6.0, 0.0))])
    times = []
    for seed in (3, 4, 5):
        log = InProcessRunner(sc, seed=seed).run()
        a = accuracy(log.t, log.wind_est, log.wind_sigma, log.wind_true, warmup_s=3.0, step_times=(5.0,))
        assert a.reconverge_s is not None and a.reconverge_s < 4.0
        times.append(a.reconverge_s)
        end = log.t > 9.0
        assert np.allclose(log.wind_est[end, :2].mean(axis=0), [-4.0, -6.0], atol=0.3)
    assert np.mean(times) < 3.0, times


def test_wind_step_does_not_move_the_force_scale():
    """Exact model, steady horizontal wind stepping by 7 m/s: the scale (driven by the vertical
    axis, frozen in transients) stays near 1 and the vertical wind near 0."""
    sc = replace(_steady((-8.0, 0.0, 0.0), 12.0, [WindChange(6.0, (-4.0, -6.0, 0.0))]), vehicle=EXACT)
    r = InProcessRunner(sc, seed=4, config=EstimatorConfig.uncalibrated())
    log = r.run()
    s, s_sig = r.estimator.force_scale
    assert r.estimator.scale_released and 0.0 < s_sig < 0.05
    assert abs(s - 1.0) < 0.015, s
    assert r.estimator.transients >= 1
    end = log.t > 10.0
    assert np.allclose(log.wind_est[end, :2].mean(axis=0), [-4.0, -6.0], atol=0.3)
    # The step leaves a vertical excursion (tilt coupling) that the OU model pulls back.
    assert abs(np.mean(log.wind_est[end, 2])) < 1.0


def test_perturbed_model_force_scale_and_horizontal_accuracy():
    """Model drawn inside the Table 5 intervals with mass errors of -2 % and +4.6 % (seeds 4, 5):
    the force scale moves towards the true/model force ratio and the horizontal 1-s error stays
    within the perturbed-model goal (0.45 m/s) on a short paper-s1 run."""
    for seed in (4, 5):
        sc = replace(load_scenario("paper-s1").with_duration(20.0), vehicle=EXACT)
        r = InProcessRunner(sc, seed=seed, perturb_model=True)
        log = r.run()
        ratio = r.params.mass_kg / r.sim.vehicle.mass_kg  # m_model / m_true
        assert abs(ratio - 1.0) > 0.015
        s, _ = r.estimator.force_scale
        assert abs(s - ratio) < 0.5 * abs(1.0 - ratio), (seed, s, ratio)
        a = accuracy(log.t, log.wind_est, log.wind_sigma, log.wind_true, warmup_s=6.0)
        assert a.rmse_horizontal_avg_ms < 0.45, (seed, a.rmse_horizontal_avg_ms)
        assert a.coverage_2sigma > 0.85, (seed, a.coverage_2sigma)


def test_two_sigma_coverage_over_seeds():
    """Horizontal 2-sigma coverage in turbulence (paper-s1, first 14 s) over several seeds."""
    cov = []
    for seed in (11, 12, 13):
        log = InProcessRunner(load_scenario("paper-s1").with_duration(14.0), seed=seed).run()
        a = accuracy(log.t, log.wind_est, log.wind_sigma, log.wind_true, warmup_s=4.0)
        cov.append(a.coverage_2sigma_axis[:2])
    c = float(np.mean(cov))
    assert 0.88 <= c <= 0.995, c


def test_presets_structure_and_selection():
    """uncalibrated = the default (force scale, OU vertical wind); calibrated = no scale,
    random-walk vertical wind, body-z accelerometer bias only; unknown names are refused."""
    assert EstimatorConfig.uncalibrated() == EstimatorConfig() == EstimatorConfig.preset("uncalibrated")
    cal = EstimatorConfig.preset("calibrated")
    assert not cal.scale_state and cal.vertical_wind_tau_s is None and cal.bias_axes == (2,)
    est = WindEstimator(load_vehicle(), cal)
    assert est.n == 7 and list(est._bias_idx) == [-1, -1, 6] and est.force_scale == (1.0, 0.0)
    exact = load_vehicle(EXACT)  # the paper's Table 5: not identified by windseek for this vehicle
    assert WindEstimator(exact).n == 7 and WindEstimator(exact)._i_scale == 6
    assert WindEstimator(load_vehicle()).config == cal  # nasa_quad's model was identified (windseek identify)
    assert EstimatorConfig.calibrated(bias_axes=(0, 2)).bias_axes == (0, 2)
    with pytest.raises(ValueError):
        EstimatorConfig.preset("factory")
    with pytest.raises(ValueError):
        WindEstimator(load_vehicle(), EstimatorConfig.calibrated(bias_axes=(3,)))
    from windseek.cmd_estimate import default_calibration

    assert PRESETS == ("calibrated", "uncalibrated")
    assert default_calibration(False) == "calibrated" and default_calibration(True) == "uncalibrated"


def test_calibrated_preset_exact_model_accuracy():
    """Exact model, paper-s1 in turbulence (first 16 s, seeds 1 and 3, turn-on z biases of
    -0.018 and -0.018 m/s^2): the calibrated preset keeps the vertical 1-s error well within
    the S1 goal (0.6 m/s) and the horizontal one within 0.3 m/s, with honest coverage; only
    the z bias is estimated and it stays within about two prior sigmas."""
    for seed in (1, 3):
        sc = replace(load_scenario("paper-s1").with_duration(16.0), vehicle=EXACT)
        r = InProcessRunner(sc, seed=seed, config=EstimatorConfig.calibrated())
        log = r.run()
        a = accuracy(log.t, log.wind_est, log.wind_sigma, log.wind_true, warmup_s=6.0)
        assert a.rmse_horizontal_avg_ms < 0.3, (seed, a.rmse_horizontal_avg_ms)
        assert a.rmse_avg_ms[2] < 0.45, (seed, a.rmse_avg_ms)
        assert 0.9 <= a.coverage_2sigma <= 0.999, (seed, a.coverage_2sigma)
        b, b_sig = r.estimator.accel_bias
        assert b[0] == b[1] == 0.0 and abs(b[2]) < 0.04 and 0.0 < b_sig[2] < 0.02, (b, b_sig)


def test_deterministic():
    sc = load_scenario("paper-s1").with_duration(1.5)
    a = InProcessRunner(sc, seed=5).run()
    b = InProcessRunner(sc, seed=5).run()
    assert np.array_equal(a.wind_est, b.wind_est)


# ------------------------------------------------------------------ bad input and gaps
def _primed() -> tuple[WindEstimator, float]:
    est = WindEstimator(load_vehicle())
    q = euler_to_quat(0.0, 0.0, 0.0)
    w = np.full(4, hover_rotor_speed(load_vehicle()))
    est.set_rotor_speeds(0.0, w)
    t = 0.0
    for k in range(50):
        t = 0.004 * (k + 1)
        est.set_attitude(t, q)
        est.imu(t, np.array([0.0, 0.0, -9.80665]), np.zeros(3))
        if k % 25 == 24:
            est.gnss_velocity(t - 0.05, np.zeros(3))
    return est, t


def test_rejects_bad_input_without_touching_state():
    est, t = _primed()
    x, P = est.state, est.covariance
    bad = [
        lambda: est.imu(t + 0.004, np.array([np.nan, 0.0, -9.8]), np.zeros(3)),
        lambda: est.imu(t + 0.004, np.array([0.0, 0.0, -1e4]), np.zeros(3)),
        lambda: est.imu(t + 0.004, np.array([0.0, 0.0, -9.8]), np.array([0.0, 100.0, 0.0])),
        lambda: est.imu(t, np.array([0.0, 0.0, -9.8]), np.zeros(3)),  # duplicate time
        lambda: est.imu(t - 0.1, np.array([0.0, 0.0, -9.8]), np.zeros(3)),  # out of order
        lambda: est.imu(math.inf, np.array([0.0, 0.0, -9.8]), np.zeros(3)),
        lambda: est.gnss_velocity(t - 0.02, np.array([np.nan, 0.0, 0.0])),
        lambda: est.gnss_velocity(t - 0.02, np.array([1e3, 0.0, 0.0])),
        lambda: est.gnss_velocity(t - 10.0, np.zeros(3)),  # older than the history
        lambda: est.set_rotor_speeds(t, np.array([400.0, -5.0, 400.0, 400.0])),
        lambda: est.set_rotor_speeds(t + 0.001, np.array([400.0, 1e6, 400.0, 400.0])),
        lambda: est.set_attitude(t + 0.001, np.array([2.0, 0.0, 0.0, 0.0])),
        lambda: est.set_attitude(t + 0.002, np.array([np.nan, 0.0, 0.0, 1.0])),
    ]
    for f in bad:
        assert f() is False
    assert np.array_equal(est.state, x) and np.array_equal(est.covariance, P)
    assert sum(est.rejected.values()) == len(bad)
    assert est.rejected["imu:bad_value"] == 3 and est.rejected["imu:duplicate_or_out_of_order"] == 2
    # Good input still goes through afterwards.
    assert est.imu(t + 0.004, np.array([0.0, 0.0, -9.80665]), np.zeros(3))


def test_gap_predicts_only_and_covariance_grows():
    est, t = _primed()
    p_before = np.trace(est.wind_cov)
    est.predict_to(t + 2.0)
    p_after = np.trace(est.wind_cov)
    assert p_after > p_before + 1.0
    assert est.t == pytest.approx(t + 2.0)
    assert est.imu(t + 2.004, np.array([0.0, 0.0, -9.80665]), np.zeros(3))


def test_not_ready_without_attitude_or_rotors():
    est = WindEstimator(load_vehicle())
    assert est.imu(0.004, np.array([0.0, 0.0, -9.8]), np.zeros(3)) is False
    assert est.rejected["imu:not_ready"] == 1


# ------------------------------------------------------------------ direction, metrics, rpm-free
def test_direction_convention_and_uncertainty():
    assert from_direction_deg(-10.0, 0.0) == pytest.approx(0.0)  # from north
    assert from_direction_deg(0.0, -10.0) == pytest.approx(90.0)  # from east
    assert from_direction_deg(-7.07, -7.07) == pytest.approx(45.0)
    s, s_sig, d, d_sig = speed_direction(np.array([0.0, -10.0, 0.0]), np.diag([0.04, 0.01, 1.0]))
    assert s == pytest.approx(10.0) and s_sig == pytest.approx(0.1)
    assert d == pytest.approx(90.0) and d_sig == pytest.approx(math.degrees(0.2 / 10.0))


def test_butterworth_matches_scipy_and_does_not_jump_at_wrap():
    f = DirectionFilter(1.0, 50.0, order=2)
    x = np.linspace(350.0, 370.0, 200) % 360.0
    y = np.array([f.update(v) for v in x])
    assert np.all(np.abs(angle_diff_deg(y[1:], y[:-1])) < 1.0)
    # Same as scipy.signal.sosfilt on the unit-vector components from steady state.
    c = np.cos(np.radians(x))
    s = np.sin(np.radians(x))
    zi = signal.sosfilt_zi(f.sos)
    yc, _ = signal.sosfilt(f.sos, c, zi=zi * c[0])
    ys, _ = signal.sosfilt(f.sos, s, zi=zi * s[0])
    assert np.allclose(y, np.degrees(np.arctan2(ys, yc)) % 360.0, atol=1e-9)


def test_metrics_reconvergence_and_average():
    t = np.arange(0.0, 10.0, 0.01)
    err = np.where((t >= 5.0) & (t < 6.5), 3.0, 0.2)
    assert reconvergence_time(t, err, 5.0) == pytest.approx(1.5, abs=0.011)
    x = np.sin(t)[:, None]
    assert np.allclose(moving_average(t, x, 1.0, centered=True)[300:700], x[300:700] * math.sin(0.5) / 0.5, atol=2e-3)


def test_motor_command_model_is_first_order_lag():
    m = MotorCommandModel(0.04, 1000.0)
    m.update(0.0, np.full(4, 300.0))
    m.update(0.004, np.full(4, 400.0))
    w = m.update(0.044, np.full(4, 400.0))
    assert np.allclose(w, 400.0 - 100.0 * math.exp(-1.0))
    assert m.update(0.044, np.full(4, 400.0)) is None  # duplicate time


# ------------------------------------------------------------------ MAVLink adapter
def _roundtrip(msgs):
    """Encode with pymavlink (windseek dialect) to bytes and decode with a fresh parser."""
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    rx = mavlink.MAVLink(None)
    out = []
    for m in msgs:
        for b in m.pack(tx):
            d = rx.parse_char(bytes([b]))
            if d is not None:
                out.append(d)
    assert len(out) == len(msgs)
    return out


@pytest.mark.parametrize("imu_kind", ["HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU"])
@pytest.mark.parametrize("att_kind", ["ATTITUDE_QUATERNION", "ATTITUDE"])
@pytest.mark.parametrize("vel_kind", ["LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT"])
@pytest.mark.parametrize("rpm_kind", ["ESC_STATUS", "RAW_RPM"])
def test_mavlink_adapter_decodes_every_kind(imu_kind, att_kind, vel_kind, rpm_kind):
    est = WindEstimator(load_vehicle())
    ad = MavlinkWindAdapter(est)
    omega = np.array([390.0, 395.0, 391.0, 396.0])
    rpm = omega * 60.0 / (2.0 * math.pi)
    roll, pitch, yaw = 0.02, -0.1, 0.3
    q = euler_to_quat(roll, pitch, yaw)
    msgs = [mavlink.MAVLink_esc_info_message(0, 1000, 1, 4, 5, 15, [0, 0, 0, 0], [0] * 4, [2500] * 4)]
    for k in range(1, 31):
        t_us = 1_000_000 + 4000 * k
        t_ms = t_us // 1000
        if rpm_kind == "ESC_STATUS":
            rpm_i = [int(round(r)) for r in rpm]
            msgs.append(mavlink.MAVLink_esc_status_message(0, t_us, rpm_i, [16.0] * 4, [5.0] * 4))
        else:
            msgs += [mavlink.MAVLink_raw_rpm_message(i, float(rpm[i])) for i in range(4)]
        if att_kind == "ATTITUDE_QUATERNION":
            msgs.append(mavlink.MAVLink_attitude_quaternion_message(t_ms, *q, 0.01, 0.02, 0.03, [1.0, 0, 0, 0]))
        else:
            msgs.append(mavlink.MAVLink_attitude_message(t_ms, roll, pitch, yaw, 0.01, 0.02, 0.03))
        acc = [1.0, 0.2, -9.9]
        gyr = [0.01, 0.02, 0.03]
        if imu_kind == "HIL_SENSOR":
            msgs.append(mavlink.MAVLink_hil_sensor_message(t_us, *acc, *gyr, 0, 0, 0, 1000, 0, 0, 20, 0x3F, 0))
        elif imu_kind == "HIGHRES_IMU":
            msgs.append(mavlink.MAVLink_highres_imu_message(t_us, *acc, *gyr, 0, 0, 0, 1000, 0, 0, 20, 0x3F, 0))
        else:
            mg = [int(round(a / 9.80665 * 1000)) for a in acc]
            msgs.append(mavlink.MAVLink_scaled_imu_message(t_ms, *mg, 10, 20, 30, 0, 0, 0, 2000))
        if k % 10 == 0:
            if vel_kind == "LOCAL_POSITION_NED":
                msgs.append(mavlink.MAVLink_local_position_ned_message(t_ms, 0, 0, -10, 1.5, -0.5, 0.2))
            elif vel_kind == "GLOBAL_POSITION_INT":
                msgs.append(mavlink.MAVLink_global_position_int_message(t_ms, 473977420, 85455940, 498000, 10000,
                                                                        150, -50, 20, 0))  # fmt: skip
            else:
                msgs.append(mavlink.MAVLink_gps_raw_int_message(t_us, 3, 473977420, 85455940, 498000, 100, 100,
                                                                158, 34157, 14))  # fmt: skip
    for m in _roundtrip(msgs):
        ad.handle(m)
    assert not est.rejected, dict(est.rejected)
    assert est.accepted["imu"] == 30
    assert est.accepted["gnss"] == 3
    assert np.allclose(est._w_rot, omega, atol=0.1)
    assert np.allclose(est._q_att, q, atol=1e-6)
    assert np.allclose(est._rates, [0.01, 0.02, 0.03], atol=1e-6)
    # The velocity fix moved the body velocity towards [1.5, -0.5] m/s NED.
    v_ned = est._R @ est.state[0:3]
    assert np.allclose(v_ned[:2], [1.5, -0.5], atol=0.25)
    # WIND_COV back out, decodable, air-mass velocity NED.
    (wc,) = _roundtrip([ad.wind_cov(10.0)])
    assert wc.get_type() == "WIND_COV"
    assert np.allclose([wc.wind_x, wc.wind_y, wc.wind_z], est.wind_ned, atol=1e-5)
    assert wc.var_horiz == pytest.approx(float(est.wind_cov[0, 0] + est.wind_cov[1, 1]), rel=1e-5)


def test_mavlink_failed_esc_blocks_rotor_speeds():
    est = WindEstimator(load_vehicle())
    ad = MavlinkWindAdapter(est)
    msgs = [
        mavlink.MAVLink_esc_info_message(0, 1000, 1, 4, 5, 15, [0, 32, 0, 0], [0] * 4, [2500] * 4),
        mavlink.MAVLink_esc_status_message(0, 2000, [3700] * 4, [16.0] * 4, [5.0] * 4),
    ]
    for m in _roundtrip(msgs):
        ad.handle(m)
    assert est._w_rot is None


def test_ground_gate_pauses_and_replaces_a_flown_filter_at_the_next_lift_off():
    from estimator.ground_gate import GroundGate

    g = GroundGate()
    assert [g.admit(True), g.admit(True)] == ["pause", "pause"]
    assert g.admit(False) == "feed"  # first lift-off: the unfed filter starts, no restart
    assert g.admit(False) == "feed"
    assert g.admit(True) == "pause"  # touchdown: kept (its figures stay readable)
    assert [g.admit(False), g.admit(False)] == ["restart", "feed"]  # next lift-off: a fresh filter
