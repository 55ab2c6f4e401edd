"""Rotation helpers (numba). Quaternions are [w, x, y, z], Hamilton convention, and rotate
body-frame (FRD) vectors into the world frame (NED): v_ned = R(q) v_frd.

Euler angles are the paper's 3-2-1 sequence (Eq. 1): R = Rz(yaw) Ry(pitch) Rx(roll), radians.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def quat_to_dcm(q: np.ndarray) -> np.ndarray:
    """Rotation matrix body (FRD) -> world (NED) from a unit quaternion."""
    R = np.empty((3, 3))
    quat_to_dcm_into(q, R)
    return R


@njit(cache=True, inline="always")
def quat_to_dcm_into(q: np.ndarray, R: np.ndarray) -> None:
    """:func:`quat_to_dcm` into ``R`` (3, 3): no allocation, for the physics tick."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True)
def dcm_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w >= 0) from a rotation matrix body -> world."""
    q = np.empty(4)
    dcm_to_quat_into(R, q)
    return q


@njit(cache=True, inline="always")
def dcm_to_quat_into(R: np.ndarray, q: np.ndarray) -> None:
    """:func:`dcm_to_quat` into ``q`` (4,): no allocation, for the controller's tick."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        q[0] = 0.25 * s
        q[1] = (R[2, 1] - R[1, 2]) / s
        q[2] = (R[0, 2] - R[2, 0]) / s
        q[3] = (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2.0
        q[0] = (R[2, 1] - R[1, 2]) / s
        q[1] = 0.25 * s
        q[2] = (R[0, 1] + R[1, 0]) / s
        q[3] = (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2.0
        q[0] = (R[0, 2] - R[2, 0]) / s
        q[1] = (R[0, 1] + R[1, 0]) / s
        q[2] = 0.25 * s
        q[3] = (R[1, 2] + R[2, 1]) / s
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2.0
        q[0] = (R[1, 0] - R[0, 1]) / s
        q[1] = (R[0, 2] + R[2, 0]) / s
        q[2] = (R[1, 2] + R[2, 1]) / s
        q[3] = 0.25 * s
    if q[0] < 0.0:
        for i in range(4):
            q[i] *= -1.0
    n = math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    for i in range(4):
        q[i] = q[i] / n


@njit(cache=True)
def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b."""
    out = np.empty(4)
    quat_mul_into(a, b, out)
    return out


@njit(cache=True, inline="always")
def quat_mul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """:func:`quat_mul` into ``out`` (4,; not ``a`` or ``b``): no allocation."""
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3]
    out[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2]
    out[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1]
    out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]


@njit(cache=True)
def quat_to_euler(q: np.ndarray) -> np.ndarray:
    """[roll, pitch, yaw] in rad (3-2-1) from a quaternion."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    sp = 2 * (w * y - z * x)
    sp = min(1.0, max(-1.0, sp))
    pitch = math.asin(sp)
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    out = np.empty(3)
    out[0] = roll
    out[1] = pitch
    out[2] = yaw
    return out


@njit(cache=True)
def euler_to_quat(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Quaternion from 3-2-1 Euler angles (rad)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = np.empty(4)
    q[0] = cr * cp * cy + sr * sp * sy
    q[1] = sr * cp * cy - cr * sp * sy
    q[2] = cr * sp * cy + sr * cp * sy
    q[3] = cr * cp * sy - sr * sp * cy
    return q


@njit(cache=True)
def tilt_angle(q: np.ndarray) -> float:
    """Angle between the body z axis and the world down axis, rad."""
    c = 1 - 2 * (q[1] * q[1] + q[2] * q[2])
    return math.acos(min(1.0, max(-1.0, c)))


# --------------------------------------------------------------------------- wind directions
# Wind is the air-mass velocity in NED; a direction is where the wind comes FROM
# (meteorological: 0 = from north, 90 = from east). These two are the only place that rule
# is written down in code.


def from_direction_deg(wind_n: float | np.ndarray, wind_e: float | np.ndarray) -> float | np.ndarray:
    """FROM-direction (deg, [0, 360)) of an air-mass velocity with north/east components (m/s)."""
    return np.mod(np.degrees(np.arctan2(-np.asarray(wind_e), -np.asarray(wind_n))), 360.0)


def velocity_from_speed_direction(speed_ms: float, from_deg: float, vertical_ms: float = 0.0
                                  ) -> tuple[float, float, float]:  # fmt: skip
    """Air-mass velocity (NED, m/s) of a wind of ``speed_ms`` blowing *from* ``from_deg`` (deg).

    The air moves toward ``from_deg + 180``; ``vertical_ms`` is the NED down component (a
    positive value is a downdraft). Example: 10 m/s from north -> ``(-10, 0, 0)``.
    ValueError on a non-finite or negative speed, a non-finite angle or vertical component.
    """
    for value, name, ok in ((speed_ms, "speed_ms", speed_ms >= 0), (from_deg, "from_deg", True),
                            (vertical_ms, "vertical_ms", True)):  # fmt: skip
        if not (math.isfinite(float(value)) and ok):
            raise ValueError(f"{name} must be a finite number{' >= 0 (m/s)' if name == 'speed_ms' else ''}, "
                             f"got {value!r}")  # fmt: skip
    rad = math.radians(float(from_deg))
    return (-float(speed_ms) * math.cos(rad), -float(speed_ms) * math.sin(rad), float(vertical_ms))
