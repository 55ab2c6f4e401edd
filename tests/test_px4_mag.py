"""PX4's magnetometer calibration redone on SCALED_IMU's raw field (``estimator/px4_mag.py``) and the compass
check fed from it (``estimator/compass_feed.py``).

The calibration: PX4's rotation enum and ``Correct()`` (a raw field made from a known body field by the
inverse calibration comes back), the slot chosen and every refusal said in one line. The live core: on a
simulated paper-s1 flight whose published heading is 12 deg off, a HIGHRES_IMU field from which an EKF2-like
bias estimate hides two thirds of the error lets the check find only the rest; with PX4's calibration the raw
SCALED_IMU field (sensor axes turned 90 deg, hard-iron offsets, soft-iron scales) gives the whole error back.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from estimator_stream import Flight, over_the_wire, record
from px4_mag_stream import FIELD, PX4_CAL, px4_params, px4_stream, raw_field

from estimator import px4_mag
from estimator.compass import CompassConfig
from estimator.live import LiveConfig, LiveCore
from sitl.simulation import T_QUAT
from vehicle.frames import quat_to_dcm
from vehicle.vehicle_file import load_vehicle


def test_px4s_rotation_enum_and_calibration_are_inverted_exactly() -> None:
    # ROTATION_YAW_90: the sensor's x axis is the body's y axis (rotate_3f(YAW_90): x' = -y, y' = x).
    assert np.allclose(px4_mag.rotation_dcm(2) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    assert np.allclose(px4_mag.rotation_dcm(8) @ [0.0, 1.0, 1.0], [0.0, -1.0, -1.0], atol=1e-12)  # ROLL_180
    for rot in range(len(px4_mag.ROTATIONS_DEG)):
        R = px4_mag.rotation_dcm(rot)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    m_body = np.array([0.21, 0.01, 0.43])
    for board, ext_rot in ((0, -1), (6, -1), (0, 2), (4, 100)):
        custom = ext_rot == 100
        p = px4_params(ROT=ext_rot, ROLL=180.0 if custom else 0.0, YAW=45.0 if custom else 0.0, **PX4_CAL)
        p["SENS_BOARD_ROT"], p["SENS_BOARD_Y_OFF"] = board, 2.0
        cal = px4_mag.from_params(p)
        assert isinstance(cal, px4_mag.Px4MagCalibration), cal
        assert cal.external == (ext_rot != -1)
        assert np.allclose(cal.correct(raw_field(cal, m_body)), m_body, atol=1e-12)
    sitl = {**px4_params(), "CAL_MAG1_ID": 197644, "CAL_MAG1_PRIO": 50, "CAL_MAG1_ROT": -1}  # PX4 SITL's two
    assert isinstance(px4_mag.from_params(sitl), px4_mag.Px4MagCalibration)
    internal = px4_mag.from_params(px4_params(**PX4_CAL))
    assert isinstance(internal, px4_mag.Px4MagCalibration)
    assert np.allclose(internal.correct(np.array([1.12, -0.05, 0.31])), internal.scale @ [1.0, 0.0, 0.0])
    assert "CAL_MAG0 (device 197388" in internal.describe() and "internal" in internal.describe()


@pytest.mark.parametrize(("change", "reason"), [
    ({"CAL_MAG1_ID": 12345, "CAL_MAG1_PRIO": 75, "CAL_MAG1_XOFF": 0.1},
     "2 compasses calibrated differently (CAL_MAG0, CAL_MAG1)"),
    ({"CAL_MAG0_ID": 0}, "no calibrated compass"),
    ({"CAL_MAG0_PRIO": 0}, "no calibrated compass"),
    ({"CAL_MAG0_XCOMP": 0.002}, "power compensation"),
    ({"CAL_MAG0_XSCALE": -1.0}, "not usable"),
    ({"CAL_MAG0_XOFF": math.nan}, "not usable"),
    ({"CAL_MAG0_ROT": 41}, "rotation 41 is not one of PX4's"),
    ({"SENS_BOARD_ROT": None}, "SENS_BOARD_ROT were not read"),
    ({"CAL_MAG0_YOFF": None}, "CAL_MAG0_YOFF were not read"),
])  # fmt: skip
def test_a_calibration_that_cannot_be_redone_says_why(change: dict[str, float | None], reason: str) -> None:
    p: dict[str, float] = px4_params()
    for k, v in change.items():
        if v is None:
            del p[k]
        else:
            p[k] = v
    cal = px4_mag.from_params(p)
    assert isinstance(cal, str) and reason in cal and "\n" not in cal


@pytest.fixture(scope="module")
def flight() -> Flight:
    """paper-s1 from hover: 10 m/s from the north with turbulence, 20 s."""
    return record(20.0)


def _offset_and_rmse(flight: Flight, cal: px4_mag.Px4MagCalibration | None, msgs: list) -> tuple[float, LiveCore]:
    core = LiveCore(LiveConfig(vehicle=load_vehicle(), compass=CompassConfig()))
    if cal is not None:
        core.use_px4_raw(cal)
    for m in over_the_wire([(1, 1, msgs)]):
        core.handle(m)
    return math.degrees(core.compass.offset_rad), core


def test_px4s_raw_field_calibrated_here_shows_the_heading_error_that_highres_imu_hides(flight: Flight) -> None:
    p = px4_params(ROT=2, **PX4_CAL)  # an external compass turned 90 deg, hard- and soft-iron errors
    cal = px4_mag.from_params(p)
    assert isinstance(cal, px4_mag.Px4MagCalibration)
    assert np.abs(raw_field(cal, quat_to_dcm(flight.truth[0, T_QUAT]).T @ FIELD)).max() < 3.0  # plausible, gauss
    msgs = px4_stream(flight, cal, err_deg=12.0, hidden_deg=8.0)
    seen_hidden, core_hr = _offset_and_rmse(flight, None, msgs)
    assert seen_hidden == pytest.approx(-4.0, abs=0.5)  # HIGHRES_IMU's field: only the third not hidden
    seen_raw, core = _offset_and_rmse(flight, cal, msgs)
    assert seen_raw == pytest.approx(-12.0, abs=0.5)  # the raw field calibrated here: all of it
    c = core.summary()["compass"]
    assert c["field"] == "px4-scaled-imu-calibrated" and c["samples"]["accepted"] > 50
    assert core_hr.summary()["compass"]["field"] == "imu-message"
    # The raw field's samples are weighed once each (SCALED_IMU repeats the last one with every IMU sample).
    assert c["samples"]["accepted"] <= sum(1 for _, m in msgs if m.get_type() == "SCALED_IMU")
    # Its stated heading sigma is the compass's alone: the autopilot's would cover what the raw field shows.
    assert core.compass_feed.heading_sigma() == pytest.approx(math.radians(1.0))
