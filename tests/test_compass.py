"""The compass check (``estimator/compass.py``): the autopilot's heading against its magnetometer.

Unit behaviour (the offset from a turned attitude, distorted samples dropped, no field without a position)
and the live core on a simulated paper-s1 flight (10 m/s) whose published attitude is 12 deg off in heading:
without the check the wind turns with it, with it the estimate stays within the same limit as the flight
without an error, and the stated uncertainty carries the compass's own.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from estimator_stream import Flight, autopilot_messages, over_the_wire, record

from estimator.compass import CompassConfig, CompassHeading
from estimator.live import LiveConfig, LiveCore
from estimator.mavlink_decode import PREFERENCE
from estimator.ukf import WindEstimator
from sitl.simulation import T_WIND
from vehicle.frames import euler_to_quat, quat_mul, quat_to_dcm
from vehicle.geomag import earth_field_ned_gauss
from vehicle.vehicle_file import load_vehicle

FIELD = np.array(earth_field_ned_gauss(47.397742, 8.545594, 488.0))  # PX4's default home, gauss NED


def _turn(q: np.ndarray, deg: float) -> np.ndarray:
    """``q`` turned by ``deg`` about NED down (Rz(deg) R)."""
    h = math.radians(deg) / 2.0
    return quat_mul(np.array([math.cos(h), 0.0, 0.0, math.sin(h)]), q)


def _heading_deg(R: np.ndarray) -> float:
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


def test_the_offset_of_a_turned_attitude_is_found_and_corrected() -> None:
    rng = np.random.default_rng(5)
    ch = CompassHeading()
    assert ch.locate(47.397742, 8.545594, 488.0)
    assert math.degrees(ch.declination_rad or 0.0) == pytest.approx(3.42, abs=0.01)
    q_true = np.asarray(euler_to_quat(math.radians(3.0), math.radians(-14.0), math.radians(30.0)))
    q_pub = _turn(q_true, -12.0)  # the autopilot's heading is 12 deg short
    for k in range(200):
        m = quat_to_dcm(q_true).T @ FIELD + 0.004 * rng.standard_normal(3)  # windseek's magnetometer noise
        ch.sample(0.02 * k, m, quat_to_dcm(q_pub))
    assert ch.ready and math.degrees(ch.offset_rad) == pytest.approx(12.0, abs=0.3)
    R = quat_to_dcm(ch.correct(q_pub))
    assert _heading_deg(R) == pytest.approx(30.0, abs=0.3)
    assert np.allclose(R[2], quat_to_dcm(q_true)[2], atol=1e-9)  # the tilt is left as published
    assert ch.sigma_rad == pytest.approx(math.radians(1.0))


def test_distorted_and_empty_samples_are_dropped_and_counted() -> None:
    ch = CompassHeading(CompassConfig(min_samples=5))
    ch.set_field(FIELD)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    R = np.eye(3)
    for k in range(20):
        ch.sample(0.02 * k, FIELD + np.array([0.0, 0.0, 0.4]), R)  # a motor current along body z: dip 76 deg
        ch.sample(0.02 * k, np.zeros(3), R)  # PX4 without a magnetometer sends zeros
        ch.sample(0.02 * k, np.array([math.nan, 0.1, 0.4]), R)
    assert not ch.ready and ch.offset_rad == 0.0 and ch.sigma_rad == 0.0
    assert ch.counters == {"distorted": 20, "no_field": 20, "bad_value": 20}
    assert np.array_equal(ch.correct(q), q)


def test_no_position_no_check() -> None:
    ch = CompassHeading()
    for k in range(100):
        ch.sample(0.02 * k, FIELD, np.eye(3))
    assert not ch.ready and ch.counters["accepted"] == 0
    assert not ch.locate(0.0, 0.0) and not ch.locate(math.nan, 8.5) and not ch.locate(91.0, 8.5)
    assert ch.counters["bad_position"] == 3
    with pytest.raises(ValueError, match="horizontal component"):
        ch.set_field((0.0, 0.0, 0.5))
    with pytest.raises(ValueError, match="compass settings"):
        CompassConfig(tau_s=0.0)


def test_the_heading_term_lies_across_the_airspeed() -> None:
    est = WindEstimator(load_vehicle())
    est.set_attitude(0.0, np.array([1.0, 0.0, 0.0, 0.0]))
    est.x[0:3] = 0.0
    est.x[3:6] = [10.0, 0.0, 0.0]  # hovering in 10 m/s from the south: the air moves north past the vehicle
    before = est.wind_cov
    est.set_heading_sigma(math.radians(2.0))
    d = est.wind_cov - before
    assert d[1, 1] == pytest.approx((10.0 * math.radians(2.0)) ** 2)  # all of it east, across the wind
    assert abs(d[0, 0]) < 1e-12 and abs(d[0, 1]) < 1e-12 and np.all(d[2] == 0.0)
    est.set_heading_sigma(math.nan)
    assert np.array_equal(est.wind_cov, before)


@pytest.fixture(scope="module")
def flight() -> Flight:
    """paper-s1 from hover: 10 m/s from the north with turbulence, 20 s."""
    return record(20.0)


def _run(flight: Flight, compass: CompassConfig, err_deg: float, mag: bool = True,
         odometry_deg: float | None = None) -> tuple[float, float, LiveCore]:  # fmt: skip
    """(horizontal RMSE m/s, 95 % coverage) of the estimates from 5 s on, and the core."""
    core = LiveCore(LiveConfig(vehicle=load_vehicle(), compass=compass))
    msgs = autopilot_messages(flight, imu="HIGHRES_IMU", imu_every=5, heading_error_deg=err_deg,
                              mag_field=tuple(FIELD) if mag else None, odometry_yaw_sigma_deg=odometry_deg)  # fmt: skip
    err2, inside, n = 0.0, 0, 0
    imu_types = set(PREFERENCE["imu"])
    truth_t = flight.truth[:, 0]
    for m in over_the_wire([(1, 1, msgs)]):
        core.handle(m)
        if m.get_type() in imu_types and (out := core.output()) is not None and out.t >= 5.0:
            w = np.array([np.interp(out.t, truth_t, flight.truth[:, T_WIND.start + i]) for i in range(2)])
            e = out.wind_ned[:2] - w
            err2 += float(e @ e)
            inside += int(e @ e <= 5.991 * (out.cov_ned[0, 0] + out.cov_ned[1, 1]) / 2.0)
            n += 1
    assert n > 100
    return math.sqrt(err2 / n), inside / n, core


def test_a_heading_error_of_the_autopilot_is_corrected_by_the_compass(flight: Flight) -> None:
    rmse_off, cov_off, _ = _run(flight, CompassConfig(enabled=False), 12.0)
    rmse_on, cov_on, core = _run(flight, CompassConfig(), 12.0)
    rmse_clean, _, _ = _run(flight, CompassConfig(enabled=False), 0.0, mag=False)
    assert rmse_off > 1.5  # 12 deg of 10 m/s: ~2 m/s across the wind
    assert cov_off < 0.5
    assert rmse_on < 0.45 and rmse_on < rmse_clean + 0.1
    assert cov_on > 0.9
    assert math.degrees(core.compass.offset_rad) == pytest.approx(-12.0, abs=0.5)
    notes = core.take_notes()
    assert any(n.startswith("compass: the autopilot's heading is checked") for n in notes)
    assert any("-12." in n and "off its magnetometer" in n for n in notes)
    c = core.summary()["compass"]
    assert c["offset_deg"] == pytest.approx(-12.0, abs=0.5) and c["sigma_deg"] == 1.0
    assert c["declination_deg"] == pytest.approx(3.42, abs=0.01) and c["samples"]["accepted"] > 100


def test_the_autopilots_own_heading_sigma_is_carried_when_larger(flight: Flight) -> None:
    """Without a usable compass, an autopilot that states its heading uncertainty (PX4's ODOMETRY) has it
    carried in the covariance: a 5 deg error inside a stated 4 deg is covered, and the check can be turned off."""
    rmse, cov, core = _run(flight, CompassConfig(), 5.0, mag=False, odometry_deg=4.0)
    assert core.compass_feed.autopilot_yaw_sigma == pytest.approx(math.radians(4.0))
    assert rmse > 0.6 and cov > 0.9  # the error is there, and stated
    _, cov_without, _ = _run(flight, CompassConfig(autopilot_sigma=False), 5.0, mag=False, odometry_deg=4.0)
    assert cov_without < 0.75


def test_px4s_raw_scaled_imu_field_is_not_taken() -> None:
    """PX4's SCALED_IMU carries sensor_mag before its calibration (offsets, scales, rotation): not a compass;
    ArduPilot fills SCALED_IMU and RAW_IMU with its calibrated field (mgauss)."""
    from estimator.mavlink_decode import magnetometer
    from wire.dialect import mavlink

    m = mavlink.MAVLink_scaled_imu_message(1000, 0, 0, -1000, 0, 0, 0, 215, 13, 432, 2000)
    assert magnetometer(m, 12) is None  # MAV_AUTOPILOT_PX4
    assert np.allclose(magnetometer(m, 3), [0.215, 0.013, 0.432])  # MAV_AUTOPILOT_ARDUPILOTMEGA
    hr = mavlink.MAVLink_highres_imu_message(1000, 0, 0, -9.8, 0, 0, 0, 0.215, 0.013, 0.432, 1013.0, 0, 0, 20.0,
                                             0x1FF, 0)  # fmt: skip
    assert np.allclose(magnetometer(hr, 12), [0.215, 0.013, 0.432])
    stale = mavlink.MAVLink_highres_imu_message(1000, 0, 0, -9.8, 0, 0, 0, 0.215, 0.013, 0.432, 1013.0, 0, 0, 20.0,
                                                0x3F, 0)  # fmt: skip
    assert magnetometer(stale, 12) is None  # accel and gyro new, the field the last one again
