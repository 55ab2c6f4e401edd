"""The wind filter's steps as numba kernels: the force model (``model_kernels``) through the
unscented arithmetic (``sigma_kernels``).

- :func:`predict`: propagate (x, P) over ``n_steps`` Euler steps of ``dt`` seconds (Eq. 49):
  sigma points of (x, P), each through the process model, unscented mean and covariance plus
  the process noise diag(q) dt (wind entries times ``wind_gain``).
- :func:`accel_innovation` / :func:`velocity_innovation`: sigma points of the current (x, P)
  through the accelerometer model (FRD specific force, m/s^2) or the NED velocity R v_body
  (m/s; the first ``nz`` components), then innovation, its covariance and the optimal gain.
  The caller may restrict the gain (the force scale's row) before
  :func:`estimator.sigma_kernels.apply_gain`.

``Work`` (and its ``Measurement`` per size) holds the scratch arrays so that no step allocates
on the Python side. Inputs held between samples: ``R`` attitude DCM body FRD -> NED, ``rates`` body rates (FRD, rad/s),
``w_rot`` rotor speeds (rad/s), ``p`` the flat vehicle parameter array.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estimator.model_kernels import accel_batch, process_batch
from estimator.sigma_kernels import innovation, sigma_points, unscented_transform


class Measurement:
    """Scratch arrays of one update with ``nz`` measurement components, ``n`` states."""

    def __init__(self, n: int, nz: int) -> None:
        self.h = np.zeros((2 * n + 1, nz))  # measurement model at each sigma point
        self.S = np.zeros((nz, nz))  # innovation covariance
        self.Pxz = np.zeros((n, nz))  # state-measurement cross covariance
        self.K = np.zeros((n, nz))  # gain
        self.y = np.zeros(nz)  # innovation
        self.Lz = np.zeros((nz, nz))  # Cholesky factor of S


class Work:
    """Scratch arrays of one filter with ``n`` states: sigma points and one :class:`Measurement`
    per measurement size (2: horizontal velocity, 3: accelerometer or 3-D velocity)."""

    def __init__(self, n: int) -> None:
        m = 2 * n + 1
        self.sig = np.zeros((m, n))  # sigma points
        self.sig_f = np.zeros((m, n))  # propagated sigma points
        self.L = np.zeros((n, n))  # Cholesky factor of c P
        self.x_new = np.zeros(n)
        self.P_new = np.zeros((n, n))
        self.meas = {2: Measurement(n, 2), 3: Measurement(n, 3)}


@njit(cache=True, nogil=True)
def predict(
    x: np.ndarray,
    P: np.ndarray,
    n_steps: int,
    dt: float,
    R: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    p: np.ndarray,
    decay_d: float,
    i_scale: int,
    fz_ref: float,
    q: np.ndarray,
    wind_gain: float,
    Wm: np.ndarray,
    Wc: np.ndarray,
    c: float,
    sig: np.ndarray,
    sig_f: np.ndarray,
    L: np.ndarray,
    x_new: np.ndarray,
    P_new: np.ndarray,
) -> int:
    """Predict (x, P) in place; returns the number of sub-steps that failed numerically (each is
    skipped: (x, P) restored with 1e-6 added to the diagonal of P, as the filter always did)."""
    n = x.shape[0]
    failed = 0
    for _ in range(n_steps):
        ok = sigma_points(x, P, c, L, sig)
        if ok:
            process_batch(sig, sig_f, dt, R, rates, w_rot, p, decay_d, i_scale, fz_ref)
            unscented_transform(sig_f, Wm, Wc, x_new, P_new)
            for i in range(n):
                qi = q[i] * dt
                if 3 <= i < 6:
                    qi *= wind_gain
                P_new[i, i] += qi
            for i in range(n):
                if not np.isfinite(x_new[i]):
                    ok = False
                for j in range(n):
                    if not np.isfinite(P_new[i, j]):
                        ok = False
        if ok:
            x[:] = x_new
            P[:, :] = P_new
        else:
            failed += 1
            for i in range(n):
                P[i, i] += 1e-6
    return failed


@njit(cache=True, nogil=True)
def accel_innovation(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    Rn: np.ndarray,
    R: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    p: np.ndarray,
    i_scale: int,
    bias_idx: np.ndarray,
    fz_ref: float,
    Wm: np.ndarray,
    Wc: np.ndarray,
    c: float,
    sig: np.ndarray,
    L: np.ndarray,
    S: np.ndarray,
    Pxz: np.ndarray,
    y: np.ndarray,
    K: np.ndarray,
    Lz: np.ndarray,
) -> bool:
    """Accelerometer update up to the gain: z = measured specific force (FRD, m/s^2), Rn its
    noise covariance (3, 3). Fills S, Pxz, y, K (3 columns). False on a numerical failure."""
    if not sigma_points(x, P, c, L, sig):
        return False
    h = accel_batch(sig, R, rates, w_rot, p, i_scale, bias_idx, fz_ref)
    return innovation(sig, x, h, Wm, Wc, Rn, z, S, Pxz, y, K, Lz)


@njit(cache=True, nogil=True)
def velocity_innovation(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    Rn: np.ndarray,
    R: np.ndarray,
    Wm: np.ndarray,
    Wc: np.ndarray,
    c: float,
    sig: np.ndarray,
    L: np.ndarray,
    h: np.ndarray,
    S: np.ndarray,
    Pxz: np.ndarray,
    y: np.ndarray,
    K: np.ndarray,
    Lz: np.ndarray,
) -> bool:
    """Velocity update up to the gain: z = NED velocity (m/s), 3 components or 2 (north, east);
    h = R v_body at each sigma point. h, S, Pxz, y, K, Lz: a ``Measurement`` of nz components."""
    if not sigma_points(x, P, c, L, sig):
        return False
    nz = z.shape[0]
    for k in range(sig.shape[0]):
        for a in range(nz):
            h[k, a] = R[a, 0] * sig[k, 0] + R[a, 1] * sig[k, 1] + R[a, 2] * sig[k, 2]
    return innovation(sig, x, h, Wm, Wc, Rn, z, S, Pxz, y, K, Lz)


__all__ = ["Measurement", "Work", "accel_innovation", "predict", "velocity_innovation"]
