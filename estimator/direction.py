"""Horizontal wind speed and FROM-direction with uncertainty; streaming Butterworth on the direction.

Wind is the air-mass velocity in NED (m/s): [-10, 0, 0] blows from the north. The
from-direction is atan2(-W_e, -W_n) in degrees, 0 = from north, 90 = from east, in [0, 360).
Uncertainties are first-order (linearized) propagations of the NED wind covariance.

The paper low-pass filters the estimated direction before using it as a heading command.
Filtering the angle itself jumps at the 0/360 wrap, so :class:`DirectionFilter` filters the
unit vector (cos, sin) of the direction and takes the angle of the result.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal


def from_direction_deg(wind_n: float | np.ndarray, wind_e: float | np.ndarray) -> float | np.ndarray:
    """FROM-direction (deg, [0, 360)) of an air-mass velocity with north/east components (m/s)."""
    return np.mod(np.degrees(np.arctan2(-np.asarray(wind_e), -np.asarray(wind_n))), 360.0)


def angle_diff_deg(a: float | np.ndarray, b: float | np.ndarray) -> float | np.ndarray:
    """Signed smallest difference a - b in degrees, in [-180, 180)."""
    return np.mod(np.asarray(a) - np.asarray(b) + 180.0, 360.0) - 180.0


def speed_direction(wind_ned: np.ndarray, cov_ned: np.ndarray) -> tuple[float, float, float, float]:
    """Horizontal speed (m/s), its 1-sigma, from-direction (deg) and its 1-sigma (deg).

    Near zero speed the direction is undefined: its sigma is reported as 180 deg.
    """
    # Scalar arithmetic: called once per filter step, where numpy's per-call cost dominated.
    wn, we = float(wind_ned[0]), float(wind_ned[1])
    c00, c01, c11 = float(cov_ned[0, 0]), 0.5 * float(cov_ned[0, 1] + cov_ned[1, 0]), float(cov_ned[1, 1])
    s2 = wn * wn + we * we
    s = math.sqrt(s2)
    d = math.degrees(math.atan2(-we, -wn)) % 360.0
    if s < 1e-6:
        return s, math.sqrt(max((c00 + c11) / 2.0, 0.0)), d, 180.0
    # Jacobians: of the speed, [wn, we] / s; of atan2(-we, -wn), [-we, wn] / s^2 (radians).
    var_s = (wn * wn * c00 + 2.0 * wn * we * c01 + we * we * c11) / s2
    var_d = (we * we * c00 - 2.0 * wn * we * c01 + wn * wn * c11) / (s2 * s2)
    s_sig = math.sqrt(max(var_s, 0.0))
    d_sig = min(math.degrees(math.sqrt(max(var_d, 0.0))), 180.0)
    return s, s_sig, d, d_sig


class DirectionFilter:
    """Causal low-pass Butterworth (scipy.signal design) on a direction, one sample at a time.

    Args:
        cutoff_hz: cutoff frequency, Hz.
        rate_hz: sample rate the filter is designed for (samples are assumed evenly spaced).
        order: Butterworth order.

    The sections are run in transposed direct form II with the same coefficients and state
    layout as ``scipy.signal.sosfilt`` (``zi`` per section); a per-sample loop over two
    channels on Python floats is several times cheaper than calling ``sosfilt`` for each sample.
    The state starts at steady state on the first sample (no start-up transient from zero).
    """

    def __init__(self, cutoff_hz: float, rate_hz: float, order: int = 2) -> None:
        if not (0.0 < cutoff_hz < rate_hz / 2.0):
            raise ValueError(f"cutoff_hz = {cutoff_hz}: must be in (0, rate_hz/2 = {rate_hz / 2})")
        self.sos = signal.butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
        self._zi0 = signal.sosfilt_zi(self.sos)  # (n_sections, 2) for a unit step
        self._sections = [tuple(float(v) for v in row) for row in self.sos]
        self.zi: list[list[list[float]]] | None = None  # [2 channels][n_sections][2]
        self.value_deg = float("nan")

    def reset(self) -> None:
        self.zi = None
        self.value_deg = float("nan")

    def update(self, direction_deg: float) -> float:
        """Feed one direction sample (deg); return the filtered direction (deg, [0, 360))."""
        if not math.isfinite(direction_deg):
            return self.value_deg
        a = math.radians(direction_deg)
        x = (math.cos(a), math.sin(a))
        if self.zi is None:
            self.zi = [(self._zi0 * x[c]).tolist() for c in range(2)]
        y = [0.0, 0.0]
        for c in range(2):
            v = x[c]
            zc = self.zi[c]
            for zs, (b0, b1, b2, _a0, a1, a2) in zip(zc, self._sections, strict=True):
                out = b0 * v + zs[0]
                zs[0] = b1 * v - a1 * out + zs[1]
                zs[1] = b2 * v - a2 * out
                v = out
            y[c] = v
        self.value_deg = math.degrees(math.atan2(y[1], y[0])) % 360.0
        return self.value_deg
