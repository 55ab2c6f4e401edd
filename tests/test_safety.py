"""The mission safety supervisor (mission.safety) and the ``windseek mission`` argument checks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mission.safety import EstimatorWatch, LinkWatchdog, SafetyLimits, Supervisor
from windseek.cli import main as cli_main
from wire.px4_modes import name as px4_mode_name

HOME = np.array([10.0, -5.0, 0.0])
LIMITS = replace(SafetyLimits(), box_min_ned=(-20.0, -10.0, -30.0), box_max_ned=(40.0, 10.0, 0.0),
                 min_altitude_m=2.0, max_altitude_m=8.0, margin_m=1.0, breach_tolerance_m=2.0)  # fmt: skip


def test_setpoints_are_clamped_into_the_box_and_altitude_band() -> None:
    sup = Supervisor(LIMITS, HOME)
    # Inside: unchanged.
    p, v = sup.clamp(np.array([20.0, 0.0, -3.0]), np.array([1.0, 0.5, 0.0]))
    assert p == pytest.approx([20.0, 0.0, -3.0]) and v == pytest.approx([1.0, 0.5, 0.0]) and sup.clamped == 0
    # Beyond the north edge, too high: on the edge minus the margin, at the ceiling; the outward
    # velocity is dropped, the inward one kept.
    p, v = sup.clamp(np.array([100.0, 0.0, -20.0]), np.array([2.0, -1.0, -1.0]))
    assert p == pytest.approx([10.0 + 40.0 - 1.0, 0.0, -8.0])
    assert v == pytest.approx([0.0, -1.0, 0.0])
    # Too low (below the minimum altitude) and west of the box.
    p, _ = sup.clamp(np.array([0.0, -50.0, -0.5]), None)
    assert p == pytest.approx([0.0, -5.0 - 10.0 + 1.0, -2.0])
    # Velocity-only setpoint at the boundary: judged at the vehicle's position.
    _, v = sup.clamp(None, np.array([0.0, 3.0, 0.0]), current=np.array([0.0, 4.0, -3.0]))
    assert v == pytest.approx([0.0, 0.0, 0.0])
    assert sup.clamped == 3
    assert sup.altitude_target(20.0) == 8.0 and sup.altitude_target(0.5) == 2.0 and sup.altitude_target(3.0) == 3.0


def test_vehicle_outside_the_box_time_limit_and_link_loss() -> None:
    sup = Supervisor(LIMITS, HOME)
    assert sup.check_vehicle(np.array([49.0, 4.0, -7.0])) is None  # inside (edge N at 50)
    assert sup.check_vehicle(np.array([51.9, 0.0, -3.0])) is None  # within the breach tolerance
    a = sup.check_vehicle(np.array([52.5, 0.0, -3.0]))
    assert a is not None and a.cause == "geofence" and "N 42.5" in a.message
    assert sup.check_vehicle(np.array([20.0, 0.0, -10.5])).cause == "geofence"  # above the 8 m ceiling + 2 m
    assert sup.check_time(299.9) is None and sup.check_time(300.0).cause == "time-limit"
    wd = LinkWatchdog(1.5)
    wd.feed(100.0)
    assert wd.check(101.4) is None
    a = wd.check(101.6)
    assert a.cause == "link-lost" and a.line().startswith("ABORT (link-lost): no telemetry for 1.6 s")


def test_estimator_watch_faults() -> None:
    cov = np.eye(3) * 0.1
    w = np.array([-5.0, 0.0, 0.0])
    ew = EstimatorWatch(max_sigma_m_s=3.0, burst=20, window_s=2.0, input_timeout_s=1.0)
    for k in range(30):  # healthy, converged; benign start-up rejections do not count
        assert ew.check(k * 0.1, w, cov, {"imu:not_ready": 50}, imu_accepted=25 * (k + 1)) is None
    assert ew.check(3.0, w * np.nan, cov, {}, 800).cause == "estimator-fault"
    assert "blew up" in ew.check(3.1, w, np.eye(3) * 10.0, {}, 801).message
    # A burst of rejected inputs within the window.
    ew = EstimatorWatch(burst=20, window_s=2.0)
    assert ew.check(0.0, w, cov, {"imu:bad_value": 0}, 1) is None
    a = ew.check(1.0, w, cov, {"imu:bad_value": 25}, 2)
    assert a.cause == "estimator-fault" and "imu:bad_value" in a.message
    # Inputs stop.
    ew = EstimatorWatch(input_timeout_s=1.0)
    assert ew.check(0.0, w, cov, {}, 10) is None and ew.check(0.9, w, cov, {}, 10) is None
    assert "no IMU sample" in ew.check(1.2, w, cov, {}, 10).message


def test_an_estimator_lagging_behind_the_telemetry_is_not_an_input_fault_until_it_is_too_late() -> None:
    """A worker thread starved on a busy machine processes the telemetry late: measured on the vehicle clock
    of the newest telemetry (a faster-than-real-time world runs it ahead) it looked like an input loss
    ("no IMU sample accepted for 2.1 s", seen in 2 of 5 PX4 walkthroughs at load 4-5)."""
    cov, w = np.eye(3) * 0.1, np.array([-5.0, 0.0, 0.0])
    ew = EstimatorWatch(input_timeout_s=2.0, max_lag_s=10.0)
    assert ew.check(10.0, w, cov, {}, 100, t_processed=10.0) is None
    # The telemetry runs 6 s ahead of what the worker has processed; its IMU count is still moving.
    assert ew.check(16.0, w, cov, {}, 100, t_processed=10.5) is None
    assert ew.check(18.0, w, cov, {}, 140, t_processed=12.0) is None
    # On its own clock the worker saw no IMU for 2 s: that is a fault, however far the telemetry is.
    assert "no IMU sample" in ew.check(19.0, w, cov, {}, 140, t_processed=14.5).message
    # Lagging more than max_lag_s is a fault of its own, said as such.
    ew = EstimatorWatch(input_timeout_s=2.0, max_lag_s=10.0)
    a = ew.check(30.0, w, cov, {}, 500, t_processed=19.0)
    assert a is not None and "behind the telemetry" in a.message and "too busy" in a.message


def test_limits_validation_and_box_text() -> None:
    assert SafetyLimits.box_from_text("10,5,0,-10,-5,-20") == ((-10.0, -5.0, -20.0), (10.0, 5.0, 0.0))
    with pytest.raises(ValueError, match="six numbers"):
        SafetyLimits.box_from_text("1,2,3")
    with pytest.raises(ValueError, match="altitude limits"):
        replace(SafetyLimits(), min_altitude_m=5.0, max_altitude_m=4.0).validate()
    with pytest.raises(ValueError, match="no altitude to fly"):
        Supervisor(replace(SafetyLimits(), box_min_ned=(-9, -9, -0.5), box_max_ned=(9, 9, 0)), np.zeros(3))


def test_px4_mode_names() -> None:
    assert px4_mode_name(6 << 16) == "OFFBOARD"
    assert px4_mode_name((4 << 16) | (3 << 24)) == "AUTO.LOITER"
    assert px4_mode_name((4 << 16) | (6 << 24)) == "AUTO.LAND"


def test_cli_mission_bad_arguments_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    rc = cli_main(["mission", "--connect", "udpin://127.0.0.1:9", "--strategy", "surge-cast", "--geofence", "1,2"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "expected six numbers" in err[0]
