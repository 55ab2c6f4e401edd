"""Input gating for the wind UKF: every raw sample is checked before it touches the filter.

Bad input (non-finite, outside physical limits, duplicate or out-of-order time stamps) is
rejected and counted by reason in :attr:`InputGate.rejected` (``"<stream>:<reason>"``); the
filter state is untouched then. Times are seconds of one clock (the autopilot's boot clock over
MAVLink, simulation time in lockstep); values are SI, FRD body / NED world.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
from numba import njit

# Physical plausibility limits for raw inputs (beyond them a sample is a fault, not data).
ACCEL_LIMIT_M_S2 = 160.0  # 16 g, a typical accelerometer range
GYRO_LIMIT_RAD_S = 35.0  # 2000 deg/s
VELOCITY_LIMIT_M_S = 100.0
QUAT_NORM_TOL = 0.1


@njit(cache=True)
def within(a: np.ndarray, lo: float, hi: float) -> bool:
    """True when every value of the 1-D array ``a`` lies in [lo, hi] (False for NaN)."""
    for i in range(a.shape[0]):  # noqa: SIM110 - a numba kernel: a loop, not a generator
        if not lo <= a[i] <= hi:
            return False
    return True


@njit(cache=True)
def norm(a: np.ndarray) -> float:
    """Euclidean norm of the 1-D array ``a`` (NaN or inf if a value is not finite)."""
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * a[i]
    return np.sqrt(s)


class InputGate:
    """Per-stream time order and value checks; counts every rejection by reason."""

    def __init__(self) -> None:
        self.rejected: Counter[str] = Counter()
        self._last_in: dict[str, float] = {}

    def reject(self, reason: str) -> bool:
        """Count a rejection; returns False (so callers can ``return gate.reject(...)``)."""
        self.rejected[reason] += 1
        return False

    def check_time(self, stream: str, t: float) -> bool:
        """True when ``t`` (s) is finite and later than the stream's last accepted sample."""
        if not math.isfinite(t):
            return self.reject(f"{stream}:bad_time")
        last = self._last_in.get(stream)
        if last is not None and t <= last:
            return self.reject(f"{stream}:duplicate_or_out_of_order")
        return True

    def mark(self, stream: str, t: float) -> None:
        """Record ``t`` as the stream's last accepted time."""
        self._last_in[stream] = t

    def attitude(self, t: float, q_wxyz: np.ndarray) -> np.ndarray | None:
        """A unit quaternion [w, x, y, z] (body FRD -> NED), or None (rejected and counted)."""
        q = np.asarray(q_wxyz, dtype=float)
        if not self.check_time("attitude", t):
            return None
        nq = norm(q) if q.shape == (4,) else math.nan
        if not abs(nq - 1.0) <= QUAT_NORM_TOL:  # also NaN / inf
            self.reject("attitude:bad_value")
            return None
        self.mark("attitude", t)
        return q / nq

    def rates(self, t: float, rates_frd: np.ndarray) -> np.ndarray | None:
        """Body rates (FRD, rad/s), or None (rejected and counted)."""
        w = np.asarray(rates_frd, dtype=float)
        if not self.check_time("rates", t):
            return None
        if w.shape != (3,) or not within(w, -GYRO_LIMIT_RAD_S, GYRO_LIMIT_RAD_S):
            self.reject("rates:bad_value")
            return None
        self.mark("rates", t)
        return w.copy()

    def rotors(self, t: float, w_rot: np.ndarray, w_max: float, n: int = 4) -> np.ndarray | None:
        """Rotor speeds (rad/s, ``n``), each in [0, 2 w_max] (the vehicle's physical range with room for an
        ESC's overshoot), or None (rejected and counted): a faulty autopilot's 1e9 never reaches the model."""
        w = np.asarray(w_rot, dtype=float)
        if not self.check_time("rotors", t):
            return None
        if w.shape != (n,) or not within(w, 0.0, 2.0 * w_max):
            self.reject("rotors:bad_value")
            return None
        self.mark("rotors", t)
        return w.copy()

    def imu(
        self, t: float, accel_frd: np.ndarray, gyro_frd: np.ndarray | None, t_filter: float | None, ready: bool
    ) -> tuple[np.ndarray, np.ndarray | None] | None:
        """(specific force FRD m/s^2, gyro FRD rad/s or None) of an IMU sample the filter may take
        at ``t``, or None (rejected and counted: bad time or value, not after the filter time
        ``t_filter``, or the filter not ``ready``)."""
        a = np.asarray(accel_frd, dtype=float)
        if not self.check_time("imu", t):
            return None
        if a.shape != (3,) or not within(a, -ACCEL_LIMIT_M_S2, ACCEL_LIMIT_M_S2):
            self.reject("imu:bad_value")
            return None
        g = None
        if gyro_frd is not None:
            g = np.asarray(gyro_frd, dtype=float)
            if g.shape != (3,) or not within(g, -GYRO_LIMIT_RAD_S, GYRO_LIMIT_RAD_S):
                self.reject("imu:bad_value")
                return None
        if t_filter is not None and t <= t_filter:
            self.reject("imu:older_than_filter")
            return None
        if not ready:
            self.reject("imu:not_ready")
            return None
        self.mark("imu", t)
        return a, g

    def velocity(self, t_valid: float, vel_ned: np.ndarray) -> np.ndarray | None:
        """A NED velocity (m/s; 3 components, or 2 = north, east), or None (rejected and counted).
        The caller marks the time once the filter has taken it (:meth:`mark` ``"gnss"``)."""
        v = np.asarray(vel_ned, dtype=float)
        if not self.check_time("gnss", t_valid):
            return None
        nz = v.shape[0] if v.ndim == 1 else 0
        if nz not in (2, 3) or not norm(v) <= VELOCITY_LIMIT_M_S:
            self.reject("gnss:bad_value")
            return None
        return v
