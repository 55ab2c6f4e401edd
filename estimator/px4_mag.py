"""PX4's magnetometer calibration applied to the raw field PX4 streams in SCALED_IMU.

Why: the compass check (:mod:`estimator.compass`) must see the field the compass measures. PX4's HIGHRES_IMU
carries the calibrated field *minus EKF2's in-flight magnetometer bias* (``src/modules/mavlink/streams/
HIGHRES_IMU.hpp``); an EKF2 whose heading drifted has explained part of the drift as a bias, so that field
hides part of the very error the check is for (three PX4 paper-s1 flights: 1.3-2.2 deg rms left after the
check on HIGHRES_IMU's field, 0.3-0.5 deg on the raw field). PX4's SCALED_IMU carries ``sensor_mag``: the
sensor's field in its own axes, before calibration (``SCALED_IMU.hpp``). This module redoes PX4's calibration
on it from PX4's own parameters, as ``src/lib/sensor_calibration/Magnetometer.hpp`` ``Correct()`` does::

    m_body = R (S (m_raw + power x COMP) - OFF)     (PX4 applies S to (m_raw - OFF); see correct())

with ``OFF = CAL_MAGn_{X,Y,Z}OFF`` [gauss], ``S`` the symmetric matrix of ``CAL_MAGn_{X,Y,Z}SCALE`` on its
diagonal and ``CAL_MAGn_{X,Y,Z}ODIAG`` (XY, XZ, YZ) off it, and ``R`` from sensor axes to the body (FRD):
an internal compass (``CAL_MAGn_ROT`` = -1, as PX4 saves it for one) follows the board,
``R = Rxyz(SENS_BOARD_{X,Y,Z}_OFF) Rot(SENS_BOARD_ROT)``; an external one ``R = Rxyz(SENS_BOARD_*_OFF)
Rot(CAL_MAGn_ROT)`` (or its ``CAL_MAGn_{ROLL,PITCH,YAW}`` for ROT 100, custom). ``Rot(k)`` is PX4's rotation
enum (``src/lib/conversion/rotation.h``: roll, pitch, yaw in degrees, the matrix a 3-2-1 Euler DCM).

Which calibration slot is SCALED_IMU's: SCALED_IMU carries ``sensor_mag`` instance 0, whose device id the
message does not say. The one enabled slot (``CAL_MAGn_ID`` != 0, ``CAL_MAGn_PRIO`` != 0) is taken, or
several when they are calibrated alike (PX4 SITL sets up two simulated compasses); otherwise the choice
would be a guess, and the calibration is refused with that reason (the check then stays on HIGHRES_IMU's
field and says so). Refused too: a power compensation (``CAL_MAGn_{X,Y,Z}COMP`` non-zero:
the battery current it scales is not in these messages) and a scale that is not positive definite.

Plain and synchronous: a parameter mapping in, a correction out. Gauss; body FRD.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

SLOTS = 4  # PX4's CAL_MAG0..3
ROTATION_CUSTOM = 100
ROTATION_INTERNAL = -1  # CAL_MAGn_ROT of an internal compass (it follows SENS_BOARD_ROT)

# PX4's enum Rotation (src/lib/conversion/rotation.h, rot_lookup): (roll, pitch, yaw) in degrees.
ROTATIONS_DEG: tuple[tuple[int, int, int], ...] = (
    (0, 0, 0), (0, 0, 45), (0, 0, 90), (0, 0, 135), (0, 0, 180), (0, 0, 225), (0, 0, 270), (0, 0, 315),
    (180, 0, 0), (180, 0, 45), (180, 0, 90), (180, 0, 135), (0, 180, 0), (180, 0, 225), (180, 0, 270),
    (180, 0, 315), (90, 0, 0), (90, 0, 45), (90, 0, 90), (90, 0, 135), (270, 0, 0), (270, 0, 45), (270, 0, 90),
    (270, 0, 135), (0, 90, 0), (0, 270, 0), (0, 180, 90), (0, 180, 270), (90, 90, 0), (180, 90, 0), (270, 90, 0),
    (90, 180, 0), (270, 180, 0), (90, 270, 0), (180, 270, 0), (270, 270, 0), (90, 180, 90), (90, 0, 270),
    (90, 68, 293), (0, 315, 0), (90, 315, 0),
)  # fmt: skip

BOARD_PARAMS = ("SENS_BOARD_ROT", "SENS_BOARD_X_OFF", "SENS_BOARD_Y_OFF", "SENS_BOARD_Z_OFF")
SLOT_FIELDS = ("ID", "PRIO", "ROT", "ROLL", "PITCH", "YAW", "XOFF", "YOFF", "ZOFF", "XSCALE", "YSCALE", "ZSCALE",
               "XODIAG", "YODIAG", "ZODIAG", "XCOMP", "YCOMP", "ZCOMP")  # fmt: skip


def param_names() -> list[str]:
    """Every PX4 parameter the calibration is built from (the board's and the four slots')."""
    return list(BOARD_PARAMS) + [f"CAL_MAG{i}_{f}" for i in range(SLOTS) for f in SLOT_FIELDS]


def euler_dcm(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """3-2-1 Euler angles [rad] -> DCM (PX4's ``matrix::Dcmf(Eulerf)``: Rz(yaw) Ry(pitch) Rx(roll))."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([[cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
                     [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
                     [-sp, sr * cp, cr * cp]])  # fmt: skip


def rotation_dcm(rot: int) -> np.ndarray:
    """PX4's rotation enum -> DCM from sensor (or board) axes to body axes."""
    if not 0 <= rot < len(ROTATIONS_DEG):
        raise ValueError(f"rotation {rot} is not one of PX4's 0..{len(ROTATIONS_DEG) - 1}")
    return euler_dcm(*(math.radians(a) for a in ROTATIONS_DEG[rot]))


@dataclass(frozen=True)
class Px4MagCalibration:
    """One compass's calibration: ``correct(m_raw) = R (S (m_raw - offset))`` (module docstring)."""

    slot: int
    device_id: int
    offset: np.ndarray  # gauss, sensor axes
    scale: np.ndarray  # 3 x 3, symmetric
    rotation: np.ndarray  # 3 x 3, sensor -> body FRD
    external: bool

    def correct(self, m_raw: np.ndarray) -> np.ndarray:
        """The raw field (gauss, sensor axes) in body FRD, calibrated. PX4's ``Correct()`` with no power term:
        ``_rotation * (_scale * (data - _offset))``."""
        return self.rotation @ (self.scale @ (np.asarray(m_raw, dtype=float) - self.offset))

    def describe(self) -> str:
        """One line: which slot, its offsets, and the rotation taken."""
        o = ", ".join(f"{v:+.3f}" for v in self.offset)
        where = "external, its CAL_MAG rotation" if self.external else "internal, the board's rotation"
        return f"CAL_MAG{self.slot} (device {self.device_id}; offsets {o} G; {where})"


def _slot(params: Mapping[str, float], i: int) -> Px4MagCalibration | str:
    """Slot ``i``'s calibration, or why it cannot be built."""

    def vec(field: str, default: float) -> np.ndarray:
        return np.array([float(params.get(f"CAL_MAG{i}_{a}{field}", default)) for a in "XYZ"])

    names = [f"CAL_MAG{i}_{f}" for f in SLOT_FIELDS if f not in ("ROLL", "PITCH", "YAW")]
    if missing := [n for n in names if n not in params]:
        more = " ..." if len(missing) > 3 else ""
        return f"PX4's calibration parameters {', '.join(missing[:3])}{more} were not read"
    if np.any(vec("COMP", 0.0) != 0.0):
        return f"CAL_MAG{i} has a power compensation (CAL_MAG{i}_xCOMP), whose current is not in these messages"
    d, od = vec("SCALE", 1.0), vec("ODIAG", 0.0)
    scale = np.array([[d[0], od[0], od[1]], [od[0], d[1], od[2]], [od[1], od[2], d[2]]])
    offset = vec("OFF", 0.0)
    if not (np.all(np.isfinite(scale)) and np.all(np.isfinite(offset)) and np.all(np.linalg.eigvalsh(scale) > 0.0)):
        return f"CAL_MAG{i}'s scale or offsets are not usable (non-finite or not positive definite)"
    level = euler_dcm(*(math.radians(float(params[f"SENS_BOARD_{a}_OFF"])) for a in "XYZ"))
    rot = int(params[f"CAL_MAG{i}_ROT"])
    try:
        if rot == ROTATION_CUSTOM:
            angles = (math.radians(float(params.get(f"CAL_MAG{i}_{a}", 0.0))) for a in ("ROLL", "PITCH", "YAW"))
            sensor = euler_dcm(*angles)
        else:
            sensor = rotation_dcm(int(params["SENS_BOARD_ROT"]) if rot == ROTATION_INTERNAL else rot)
    except ValueError as e:
        return f"CAL_MAG{i}: {e}"
    return Px4MagCalibration(slot=i, device_id=int(params[f"CAL_MAG{i}_ID"]), offset=offset, scale=scale,
                             rotation=level @ sensor, external=rot != ROTATION_INTERNAL)  # fmt: skip


def enabled_slots(params: Mapping[str, float]) -> list[int]:
    """The slots with a device (``CAL_MAGn_ID`` != 0) and a non-zero priority."""
    return [i for i in range(SLOTS) if int(params.get(f"CAL_MAG{i}_ID", 0)) != 0
            and int(params.get(f"CAL_MAG{i}_PRIO", -1)) != 0]  # fmt: skip


def from_params(params: Mapping[str, float]) -> Px4MagCalibration | str:
    """The calibration of SCALED_IMU's compass from PX4's parameters, or the reason it cannot be built (one
    line). ``params`` maps names to values as PARAM_VALUE carried them (INT32s already decoded). With several
    enabled slots the calibration is taken only when they are all the same (PX4 SITL configures two simulated
    compasses, both uncalibrated): which one SCALED_IMU carries then does not matter."""
    missing = [n for n in BOARD_PARAMS if n not in params]
    if missing:
        return f"PX4's board parameters {', '.join(missing)} were not read"
    enabled = enabled_slots(params)
    if not enabled:
        return "PX4 has no calibrated compass (no CAL_MAGn_ID with a non-zero priority)"
    cals = [_slot(params, i) for i in enabled]
    if reasons := [c for c in cals if isinstance(c, str)]:
        return reasons[0]
    first = cals[0]
    assert isinstance(first, Px4MagCalibration)
    if any(not (np.allclose(c.offset, first.offset, atol=1e-6) and np.allclose(c.scale, first.scale, atol=1e-6)
                and np.allclose(c.rotation, first.rotation, atol=1e-9)) for c in cals[1:] if not isinstance(c, str)):
        ids = ", ".join(f"CAL_MAG{i}" for i in enabled)
        return (f"PX4 has {len(enabled)} compasses calibrated differently ({ids}) and SCALED_IMU does not say which "
                "it carries")  # fmt: skip
    return first


__all__ = ["Px4MagCalibration", "enabled_slots", "euler_dcm", "from_params", "param_names", "rotation_dcm"]
