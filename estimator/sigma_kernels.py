"""Unscented Kalman filter arithmetic as numba kernels (the estimator's hot path).

The same algorithm as filterpy's ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints``
(van der Merwe's scaled sigma points, unscented transform with additive noise), written out
over the small fixed-size arrays of the wind filter so that one filter step is a few compiled
calls instead of some hundred numpy calls. ``tests/test_estimator_reference.py`` runs the
wind filter and filterpy's UnscentedKalmanFilter side by side on simulated flight data and
checks that they agree; filterpy stays the reference.

Shapes: n states, m = 2 n + 1 sigma points, nz measurement components. Every function works
in place on caller-owned arrays (no allocation on the hot path) and returns False instead of
raising on a numerical failure (a covariance that is not positive definite, a non-finite
result), leaving the filter state untouched; the caller counts it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


def merwe_weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Mean weights Wm, covariance weights Wc (length 2 n + 1) and the sigma-point spread
    c = n + lambda, lambda = alpha^2 (n + kappa) - n (filterpy ``MerweScaledSigmaPoints``)."""
    lam = alpha**2 * (n + kappa) - n
    w = 0.5 / (n + lam)
    Wm = np.full(2 * n + 1, w)
    Wc = np.full(2 * n + 1, w)
    Wm[0] = lam / (n + lam)
    Wc[0] = lam / (n + lam) + (1.0 - alpha**2 + beta)
    return Wm, Wc, float(n + lam)


@njit(cache=True)
def cholesky_lower(A: np.ndarray, scale: float, L: np.ndarray) -> bool:
    """L lower-triangular with L L^T = scale * A (A symmetric). False when not positive definite."""
    n = A.shape[0]
    for j in range(n):
        s = scale * A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:  # also catches NaN
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = scale * A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(cache=True)
def sigma_points(x: np.ndarray, P: np.ndarray, c: float, L: np.ndarray, out: np.ndarray) -> bool:
    """Scaled sigma points of (x, P): out[0] = x, out[1 + k] = x + col_k, out[1 + n + k] = x - col_k,
    where col_k is column k of the Cholesky factor of c P (c = n + lambda). ``L``: (n, n) scratch."""
    n = x.shape[0]
    if not cholesky_lower(P, c, L):
        return False
    for i in range(n):
        out[0, i] = x[i]
    for k in range(n):
        for i in range(n):
            out[1 + k, i] = x[i] + L[i, k]
            out[1 + n + k, i] = x[i] - L[i, k]
    return True


@njit(cache=True)
def unscented_transform(sig: np.ndarray, Wm: np.ndarray, Wc: np.ndarray, x: np.ndarray, P: np.ndarray) -> None:
    """Weighted mean ``x`` and covariance ``P`` (without noise) of the points ``sig`` (m, n)."""
    m, n = sig.shape
    for i in range(n):
        s = 0.0
        for k in range(m):
            s += Wm[k] * sig[k, i]
        x[i] = s
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(m):
                s += Wc[k] * (sig[k, i] - x[i]) * (sig[k, j] - x[j])
            P[i, j] = s
            P[j, i] = s


@njit(cache=True)
def innovation(
    sig: np.ndarray,
    x: np.ndarray,
    h: np.ndarray,
    Wm: np.ndarray,
    Wc: np.ndarray,
    Rn: np.ndarray,
    z: np.ndarray,
    S: np.ndarray,
    Pxz: np.ndarray,
    y: np.ndarray,
    K: np.ndarray,
    L: np.ndarray,
) -> bool:
    """Innovation covariance S = cov(h) + Rn, cross covariance Pxz = cov(sig, h), innovation
    y = z - mean(h) and the optimal gain K = Pxz S^-1 (through the Cholesky factor of S).

    ``sig`` (m, n): the sigma points of (x, P); ``h`` (m, nz): the measurement model at each;
    ``L``: (nz, nz) scratch. False when S is not positive definite.
    """
    m, nz = h.shape
    n = x.shape[0]
    zp = np.zeros(nz)
    for a in range(nz):
        s = 0.0
        for k in range(m):
            s += Wm[k] * h[k, a]
        zp[a] = s
        y[a] = z[a] - s
    for a in range(nz):
        for b in range(a, nz):
            s = 0.0
            for k in range(m):
                s += Wc[k] * (h[k, a] - zp[a]) * (h[k, b] - zp[b])
            S[a, b] = s + Rn[a, b]
            S[b, a] = s + Rn[b, a]
    for i in range(n):
        for a in range(nz):
            s = 0.0
            for k in range(m):
                s += Wc[k] * (sig[k, i] - x[i]) * (h[k, a] - zp[a])
            Pxz[i, a] = s
    if not cholesky_lower(S, 1.0, L):
        return False
    # K S = Pxz, S = L L^T: solve row by row (forward, then backward substitution).
    for i in range(n):
        for a in range(nz):
            s = Pxz[i, a]
            for b in range(a):
                s -= K[i, b] * L[a, b]
            K[i, a] = s / L[a, a]
        for a in range(nz - 1, -1, -1):
            s = K[i, a]
            for b in range(a + 1, nz):
                s -= K[i, b] * L[b, a]
            K[i, a] = s / L[a, a]
    return True


@njit(cache=True, nogil=True)
def apply_gain(
    x: np.ndarray,
    P: np.ndarray,
    K: np.ndarray,
    S: np.ndarray,
    Pxz: np.ndarray,
    y: np.ndarray,
    general: bool,
    x_new: np.ndarray,
    P_new: np.ndarray,
) -> bool:
    """x + K y and the updated covariance, symmetrized; written to x and P only when finite.

    ``general``: P - K Pxz^T - Pxz K^T + K S K^T, valid for any gain (a restricted, suboptimal
    one); otherwise P - K S K^T (the optimal gain). ``x_new``, ``P_new``: scratch.
    """
    n, nz = K.shape
    for i in range(n):
        s = x[i]
        for a in range(nz):
            s += K[i, a] * y[a]
        x_new[i] = s
    for i in range(n):
        for j in range(n):
            kskt = 0.0
            for a in range(nz):
                ks = 0.0
                for b in range(nz):
                    ks += K[i, b] * S[b, a]
                kskt += ks * K[j, a]
            if general:
                v = P[i, j] + kskt
                for a in range(nz):
                    v -= K[i, a] * Pxz[j, a] + Pxz[i, a] * K[j, a]
            else:
                v = P[i, j] - kskt
            P_new[i, j] = v
    for i in range(n):
        if not math.isfinite(x_new[i]):
            return False
        for j in range(n):
            if not math.isfinite(P_new[i, j]):
                return False
    for i in range(n):
        x[i] = x_new[i]
        for j in range(n):
            P[i, j] = 0.5 * (P_new[i, j] + P_new[j, i])
    return True
