"""Fit and prediction metrics of a model output ``y`` against measurements ``z`` (the paper's Tables 1
and 4; Klein & Morelli, *Aircraft System Identification*, 2006, ch. 5 for R^2 and s^2; Theil's
coefficient after H. Theil, *Applied Economic Forecasting*, 1966).

All functions take two 1-D arrays of the same length, in the same physical units (e.g. N or N m), and
raise ``ValueError`` naming the problem for empty, mismatched or non-finite inputs and for the
degenerate cases where a metric is undefined:

- ``r_squared``: coefficient of determination ``1 - sum (z - y)^2 / sum (z - mean z)^2`` (a fraction;
  the paper's Table 1 prints it in percent);
- ``s_squared``: fit error variance ``sum (z - y)^2 / (N - n_p)`` (units squared, Table 1);
- ``tic``: Theil's inequality coefficient ``rms(z - y) / (rms(z) + rms(y))``, between 0 (perfect) and 1
  (Eq. 47, Table 4). The paper's typeset Eq. 47 shows one square root over the sum of both mean
  squares; Theil's coefficient as Klein & Morelli define it (and the "normalized between 0 and 1" the
  paper states) has the sum of the two root mean squares, which is what is computed here;
- ``nrmse``: ``rms(z - y) / (max z - min z)`` (Eq. 48, Table 4).
"""

from __future__ import annotations

import math

import numpy as np


def r_squared(z: np.ndarray, y: np.ndarray) -> float:
    """Coefficient of determination of ``y`` for ``z`` (fraction, at most 1; centred on the mean of z)."""
    zz, yy = _pair(z, y)
    sst = float(np.sum((zz - zz.mean()) ** 2))
    if not sst > 0.0:
        raise ValueError("z is constant: R^2 is undefined")
    return 1.0 - float(np.sum((zz - yy) ** 2)) / sst


def s_squared(z: np.ndarray, y: np.ndarray, n_params: int) -> float:
    """Fit error variance ``sum (z - y)^2 / (N - n_params)`` (units of z, squared)."""
    zz, yy = _pair(z, y)
    if n_params < 0 or zz.size <= n_params:
        raise ValueError(f"need 0 <= n_params < N, got n_params={n_params}, N={zz.size}")
    return float(np.sum((zz - yy) ** 2)) / (zz.size - n_params)


def tic(z: np.ndarray, y: np.ndarray) -> float:
    """Theil's inequality coefficient ``rms(z - y) / (rms(z) + rms(y))``: 0 perfect, 1 for ``y = 0``."""
    zz, yy = _pair(z, y)
    den = _rms(zz) + _rms(yy)
    if not den > 0.0:
        raise ValueError("z and y are both all zero: TIC is undefined")
    return _rms(zz - yy) / den


def nrmse(z: np.ndarray, y: np.ndarray) -> float:
    """Root mean squared error of ``y`` normalized by the range of ``z``."""
    zz, yy = _pair(z, y)
    span = float(np.ptp(zz))
    if not span > 0.0:
        raise ValueError("z is constant: its range is zero and NRMSE is undefined")
    return _rms(zz - yy) / span


def _rms(x: np.ndarray) -> float:
    return math.sqrt(float(np.mean(x * x)))


def _pair(z: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    zz, yy = as_finite_1d("z", z), as_finite_1d("y", y)
    if zz.size != yy.size:
        raise ValueError(f"z and y differ in length: {zz.size} and {yy.size}")
    return zz, yy


def as_finite_1d(name: str, x: np.ndarray) -> np.ndarray:
    """``x`` as a non-empty 1-D float array of finite values, or ``ValueError`` naming ``name``."""
    a = np.asarray(x, dtype=float)
    if a.ndim != 1 or a.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array, got shape {a.shape}")
    bad = np.nonzero(~np.isfinite(a))[0]
    if bad.size:
        raise ValueError(f"{name} has {bad.size} non-finite value(s) (NaN or inf), the first at index {bad[0]}")
    return a
