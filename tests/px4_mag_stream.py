"""PX4-like message streams for the compass tests: PX4's magnetometer parameters and a flight whose
HIGHRES_IMU field hides part of a heading error while SCALED_IMU carries the raw field (``tests/test_px4_mag.py``,
``tests/test_estimator_px4_mag_cli.py``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from estimator_stream import Flight, autopilot_messages

from estimator import px4_mag
from sitl.simulation import T_QUAT
from vehicle.frames import quat_to_dcm
from vehicle.geomag import earth_field_ned_gauss
from wire.dialect import mavlink

FIELD = np.array(earth_field_ned_gauss(47.397742, 8.545594, 488.0))  # PX4's default home, gauss NED


def px4_params(**slot0: float) -> dict[str, float]:
    """A PX4 parameter set with one internal compass in slot 0 (defaults as PX4's), ``slot0`` overriding."""
    p: dict[str, float] = {"SENS_BOARD_ROT": 0, **{f"SENS_BOARD_{a}_OFF": 0.0 for a in "XYZ"}}
    for i in range(px4_mag.SLOTS):
        for f in px4_mag.SLOT_FIELDS:
            p[f"CAL_MAG{i}_{f}"] = 1.0 if f.endswith("SCALE") else (-1.0 if f in ("ROT", "PRIO") and i == 0 else 0.0)
    p["CAL_MAG0_ID"], p["CAL_MAG0_PRIO"] = 197388, 50
    p.update({f"CAL_MAG0_{k}": v for k, v in slot0.items()})
    return p


PX4_CAL = dict(XOFF=0.12, YOFF=-0.05, ZOFF=0.31, XSCALE=1.08, YSCALE=0.95, ZSCALE=1.02, XODIAG=0.03, YODIAG=-0.02,
           ZODIAG=0.01)  # fmt: skip


def raw_field(cal: px4_mag.Px4MagCalibration, m_body: np.ndarray) -> np.ndarray:
    """The raw sensor field that calibrates to ``m_body`` (PX4's Correct() inverted)."""
    return np.linalg.solve(cal.scale, cal.rotation.T @ m_body) + cal.offset


def px4_stream(flight: Flight, cal: px4_mag.Px4MagCalibration, err_deg: float,
               hidden_deg: float) -> list[tuple[float, Any]]:
    """PX4-like messages: the published heading ``err_deg`` off; HIGHRES_IMU's field that of the Earth's field
    turned by ``hidden_deg`` about down (the part an EKF2 bias estimate hides: the field agrees with the wrong
    heading that much); and
    after every fifth HIGHRES_IMU, a SCALED_IMU with its accelerometer and gyro (mG, mrad/s) and the raw field
    (mgauss) that ``cal`` calibrates to the truth."""
    h = -math.radians(hidden_deg)  # the field turned the way the published heading is
    hidden_field = np.array([[math.cos(h), -math.sin(h), 0.0], [math.sin(h), math.cos(h), 0.0], [0, 0, 1.0]]) @ FIELD
    truth_t = flight.truth[:, 0]
    msgs: list[tuple[float, Any]] = []
    n = 0
    for t, m in autopilot_messages(flight, imu="HIGHRES_IMU", imu_every=5, heading_error_deg=err_deg,
                                   mag_field=tuple(FIELD)):  # fmt: skip
        if m.get_type() == "HIGHRES_IMU":
            true_b = np.array([m.xmag, m.ymag, m.zmag])
            R = quat_to_dcm(flight.truth[min(int(np.searchsorted(truth_t, t - 1e-9)), len(truth_t) - 1), T_QUAT])
            m.xmag, m.ymag, m.zmag = (float(v) for v in R.T @ hidden_field)
            n += 1
            if n % 5 == 0:
                raw = np.rint(raw_field(cal, true_b) * 1000.0).astype(int)
                msgs.append((t, m))
                mg = [int(round(a / 9.80665 * 1000.0)) for a in (m.xacc, m.yacc, m.zacc)]
                mr = [int(round(g * 1000.0)) for g in (m.xgyro, m.ygyro, m.zgyro)]
                m = mavlink.MAVLink_scaled_imu_message(int(round(t * 1e3)), *mg, *mr, *raw, 2000)
        msgs.append((t, m))
    return msgs


