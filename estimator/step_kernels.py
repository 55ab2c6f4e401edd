"""The wind filter's steps as numba kernels: the force model (``model_kernels``) through the
unscented arithmetic (``sigma_kernels``).

- :func:`predict`: propagate (x, P) over ``n_steps`` Euler steps of ``dt`` seconds (Eq. 49):
  sigma points of (x, P), each through the process model, unscented mean and covariance plus
  the process noise diag(q) dt (wind entries times ``wind_gain``).
- :func:`accel_step`: one IMU step in one compiled call: :func:`predict`, :func:`accel_innovation`,
  the transient detector (:func:`watch_innovation`), the force scale's restricted gain and
  :func:`estimator.sigma_kernels.apply_gain`.
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

import math

import numpy as np
from numba import njit

from estimator.model_kernels import accel_batch, process_batch
from estimator.sigma_kernels import apply_gain, innovation, sigma_points, unscented_transform

# The transient detector's state (``det``, see :func:`watch_innovation`): its indices.
#: Low-passed normalized horizontal accelerometer innovation (x, y) and its slow baseline (x, y).
D_EMA, D_SLOW = 0, 2
#: Seconds the detector has been firing without a break; seconds the force scale stays frozen.
D_FIRING, D_LEFT = 4, 5
#: Wind process-noise multiplier (> 1 while a transient is detected); times the detector fired.
D_Q_GAIN, D_COUNT = 6, 7
D_SIZE = 8
# Its settings (``det_cfg``): the threshold on the normalized innovation, the longest firing (s),
# the hold of the force scale (s), the wind process-noise multiplier while firing.
C_THRESHOLD, C_MAX_S, C_HOLD_S, C_Q_GAIN = 0, 1, 2, 3


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


def detector(threshold: float, max_s: float, hold_s: float, q_gain: float) -> tuple[np.ndarray, np.ndarray]:
    """A transient detector's initial state (quiet: wind process-noise multiplier 1) and its settings
    array for :func:`watch_innovation` (see there; ``EstimatorConfig.transient_*``)."""
    det = np.zeros(D_SIZE)
    det[D_Q_GAIN] = 1.0
    cfg = np.zeros(4)
    cfg[C_THRESHOLD], cfg[C_MAX_S], cfg[C_HOLD_S], cfg[C_Q_GAIN] = threshold, max_s, hold_s, q_gain
    return det, cfg


@njit(cache=True, nogil=True)
def watch_innovation(y: np.ndarray, S: np.ndarray, det: np.ndarray, a: float, b: float, dt: float,
                     cfg: np.ndarray) -> None:  # fmt: skip
    """Transient detector: a low-passed normalized horizontal accelerometer innovation far from its
    slow baseline means the wind is changing faster than its random walk. While it fires (at most
    ``cfg[C_MAX_S]`` s without a break) the wind process noise is raised (``det[D_Q_GAIN]``) and the
    force scale is frozen for ``cfg[C_HOLD_S]`` s (``det[D_LEFT]``): a wind step must not be explained
    by a mass change. Innovations that stay biased longer are model error: then neither.

    ``y``, ``S``: the accelerometer innovation (FRD, m/s^2) and its covariance; only x and y enter.
    ``a``, ``b``: the low-pass and baseline weights of this step; ``dt``: the span it closes (s).
    ``det`` (:data:`D_SIZE`): the detector's state, updated in place; ``cfg``: its settings.
    """
    d = 0.0
    for k in range(2):
        nu = y[k] / math.sqrt(S[k, k])
        det[D_EMA + k] = (1.0 - a) * det[D_EMA + k] + a * nu
        det[D_SLOW + k] = (1.0 - b) * det[D_SLOW + k] + b * nu
        v = abs(det[D_EMA + k] - det[D_SLOW + k])
        if v > d:
            d = v
    if d > cfg[C_THRESHOLD]:
        if det[D_FIRING] == 0.0:
            det[D_COUNT] += 1.0
        det[D_FIRING] += dt
        if det[D_FIRING] <= cfg[C_MAX_S]:
            det[D_LEFT] = cfg[C_HOLD_S]
            det[D_Q_GAIN] = cfg[C_Q_GAIN]
        else:
            det[D_LEFT] = 0.0
            det[D_Q_GAIN] = 1.0
    else:
        det[D_FIRING] = 0.0
        det[D_Q_GAIN] = 1.0


@njit(cache=True, nogil=True)
def accel_step(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, Rn: np.ndarray, R: np.ndarray, rates: np.ndarray,
    w_rot: np.ndarray, p: np.ndarray, n_steps: int, dt: float, decay_d: float, fz_pred: float, fz_ref: float,
    q: np.ndarray, i_scale: int, bias_idx: np.ndarray, learn_scale: bool, Wm: np.ndarray, Wc: np.ndarray,
    c: float, det: np.ndarray, det_cfg: np.ndarray, a: float, b: float, dt_last: float, w: tuple, m: tuple,
    nis: tuple,
) -> tuple[int, int]:  # fmt: skip
    """One IMU step: :func:`predict` over ``n_steps`` of ``dt`` s (with ``fz_pred``, the low-passed body-z
    specific force before this sample), then the accelerometer update with ``z`` (FRD, m/s^2), noise ``Rn``
    and ``fz_ref`` (after it): :func:`accel_innovation`, :func:`watch_innovation` (weights ``a``, ``b``;
    ``dt_last``: the last prediction span, s), the force scale's gain row restricted to the body-z
    innovation (zero unless ``learn_scale`` and the detector's hold is over), and
    :func:`estimator.sigma_kernels.apply_gain` in the general form.

    ``w``: (sig, sig_f, L, x_new, P_new) of :class:`Work`; ``m``: (S, Pxz, y, K, Lz) of a 3-component
    :class:`Measurement`; ``nis``: (y, S) copied there when the innovation succeeded. A failed update
    leaves (x, P) as they were with 1e-6 added to the diagonal of P. Returns (failed prediction
    sub-steps, update status: 0 done, 1 innovation failed, 2 gain failed).
    """
    sig, sig_f, L, x_new, P_new = w
    S, Pxz, y, K, Lz = m
    failed = predict(x, P, n_steps, dt, R, rates, w_rot, p, decay_d, i_scale, fz_pred, q, det[D_Q_GAIN], Wm, Wc, c,
                     sig, sig_f, L, x_new, P_new)  # fmt: skip
    status = 1
    if accel_innovation(x, P, z, Rn, R, rates, w_rot, p, i_scale, bias_idx, fz_ref, Wm, Wc, c, sig, L, S, Pxz, y,
                        K, Lz):  # fmt: skip
        watch_innovation(y, S, det, a, b, dt_last, det_cfg)
        nis[0][:] = y
        nis[1][:, :] = S
        if i_scale >= 0:
            K[i_scale, :] = 0.0
            if learn_scale and det[D_LEFT] <= 0.0:
                K[i_scale, 2] = Pxz[i_scale, 2] / S[2, 2]
        status = 0 if apply_gain(x, P, K, S, Pxz, y, i_scale >= 0, x_new, P_new) else 2
    if status:
        for i in range(x.shape[0]):
            P[i, i] += 1e-6
    return failed, status


__all__ = ["Measurement", "Work", "accel_innovation", "accel_step", "detector", "predict", "velocity_innovation",
           "watch_innovation"]
