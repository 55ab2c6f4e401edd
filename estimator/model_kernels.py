"""The estimator's force model as numba kernels: specific force, process step, accelerometer model.

The force model is the simulator's own ``vehicle.rotor_model.rotor_wrench`` (paper Eq. 40-46),
called from here, so the estimator and the simulator cannot drift apart. Frames and units: state
x = [u, v, w] body velocity (FRD, m/s), [W_n, W_e, W_d] wind (air-mass velocity NED, m/s), then
the optional force scale and accelerometer biases (see :class:`estimator.config.EstimatorConfig`);
``R`` is the attitude DCM body FRD -> NED, ``rates`` body rates (FRD, rad/s), ``w_rot`` rotor
speeds (rad/s), ``p`` the flat vehicle parameter array (``vehicle.params``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from vehicle.params import MAX_ROTORS, P_G, P_MASS
from vehicle.rotor_model import N_COEF, rotor_wrench_into


@njit(cache=True)
def specific_force(
    x: np.ndarray, R: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, p: np.ndarray, i_scale: int, fz_ref: float
) -> np.ndarray:
    """Model specific force (FRD, m/s^2) at state x: rotor forces over mass at the airspeed.

    With a force-scale state s = ``x[i_scale]`` (``i_scale >= 0``, dimensionless, 1 =
    nominal): s * F_x / m, s * F_y / m and F_z / m + (s - 1) * fz_ref, where ``fz_ref`` is the
    low-passed measured body-z specific force (m/s^2). To first order in s - 1 this is s * F / m
    (a mass error); the z correction leaves out the fast thrust fluctuations on purpose (see
    EstimatorConfig.scale_state).
    """
    out = np.empty(3)
    specific_force_into(x, R, rates, w_rot, p, i_scale, fz_ref, ForceScratch(), out)
    return out


#: Scratch arrays of :func:`specific_force_into`: airspeed (3, FRD m/s), zero rotor accelerations
#: (MAX_ROTORS), the regressors (N_COEF) and the wrench (6).
ForceScratchT = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


@njit(cache=True)
def ForceScratch() -> ForceScratchT:  # noqa: N802 - named as the type it makes
    """New :data:`ForceScratchT` arrays (allocated once per batch of sigma points)."""
    return np.empty(3), np.zeros(MAX_ROTORS), np.empty(N_COEF), np.empty(6)


@njit(cache=True, inline="always")
def specific_force_into(
    x: np.ndarray, R: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, p: np.ndarray, i_scale: int, fz_ref: float,
    scratch: ForceScratchT, out: np.ndarray,
) -> None:  # fmt: skip
    """:func:`specific_force` into ``out`` (3,), with ``scratch`` (:func:`ForceScratch`): no allocation."""
    v_air, w_dot, reg, fm = scratch
    W0, W1, W2 = x[3], x[4], x[5]
    for i in range(3):
        # R^T W: the wind (NED) seen in body axes.
        v_air[i] = x[i] - (R[0, i] * W0 + R[1, i] * W1 + R[2, i] * W2)
    rotor_wrench_into(v_air, rates, w_rot, w_dot, p, reg, fm)
    im = 1.0 / p[P_MASS]
    if i_scale >= 0:
        sc = x[i_scale]
        out[0] = fm[0] * im * sc
        out[1] = fm[1] * im * sc
        out[2] = fm[2] * im + (sc - 1.0) * fz_ref
    else:
        out[0] = fm[0] * im
        out[1] = fm[1] * im
        out[2] = fm[2] * im


@njit(cache=True)
def process_batch(
    sigmas: np.ndarray,
    out: np.ndarray,
    dt: float,
    R: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    p: np.ndarray,
    decay_d: float,
    i_scale: int,
    fz_ref: float,
) -> None:
    """Propagate every sigma point by one Euler step of Eq. 49. Wind, scale and bias: random
    walks, except the vertical wind, multiplied by ``decay_d`` (Ornstein-Uhlenbeck, see
    EstimatorConfig; 1 = random walk)."""
    g = p[P_G]
    pr, qr, rr = rates[0], rates[1], rates[2]
    scratch = ForceScratch()
    f = np.empty(3)
    for k in range(sigmas.shape[0]):
        x = sigmas[k]
        specific_force_into(x, R, rates, w_rot, p, i_scale, fz_ref, scratch, f)
        u, v, w = x[0], x[1], x[2]
        # Gravity in body axes is the third row of R (R^T [0, 0, g]); the rates x v term is
        # the rotation of the body axes the velocity is expressed in.
        du = f[0] + R[2, 0] * g - (qr * w - rr * v)
        dv = f[1] + R[2, 1] * g - (rr * u - pr * w)
        dw = f[2] + R[2, 2] * g - (pr * v - qr * u)
        out[k, :] = x
        out[k, 0] = u + dt * du
        out[k, 1] = v + dt * dv
        out[k, 2] = w + dt * dw
        out[k, 5] = x[5] * decay_d


@njit(cache=True)
def accel_batch(
    sigmas: np.ndarray,
    R: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    p: np.ndarray,
    i_scale: int,
    bias_idx: np.ndarray,
    fz_ref: float,
) -> np.ndarray:
    """Accelerometer measurement model at every sigma point: f(v_air) (with the force scale)
    + bias; ``bias_idx[i]`` is the state index of the body-axis-i bias, -1 = no bias state."""
    n = sigmas.shape[0]
    out = np.empty((n, 3))
    scratch = ForceScratch()
    f = np.empty(3)
    for k in range(n):
        specific_force_into(sigmas[k], R, rates, w_rot, p, i_scale, fz_ref, scratch, f)
        for i in range(3):
            j = bias_idx[i]
            out[k, i] = f[i] + (sigmas[k, j] if j >= 0 else 0.0)
    return out


#: Wind step of the central differences in :func:`unseen_bias_wind_cov` [m/s].
_DW = 0.2


@njit(cache=True)
def unseen_bias_wind_cov(
    x: np.ndarray, R: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, p: np.ndarray, i_scale: int, fz_ref: float,
    sigma_b: float, cap: float,
) -> np.ndarray:  # fmt: skip
    """Horizontal wind covariance (N, E; (m/s)^2) from an accelerometer bias the filter cannot see.

    At a constant heading a body-fixed horizontal accelerometer bias b (FRD x, y) and a wind change
    move the measured specific force alike, so the filter reads b as wind: dW = -J^-1 b with
    J = d f_xy / d W_ne (2 x 2, from the force model by central differences of ``_DW``). With b
    isotropic of 1-sigma ``sigma_b`` [m/s^2]: cov = sigma_b^2 (J^T J)^-1. Where J is nearly singular
    (no drag to speak of) each variance is capped at ``cap`` [(m/s)^2].
    """
    J = np.empty((2, 2))
    for col in range(2):
        xp = x.copy()
        xm = x.copy()
        xp[3 + col] += _DW
        xm[3 + col] -= _DW
        fp = specific_force(xp, R, rates, w_rot, p, i_scale, fz_ref)
        fm = specific_force(xm, R, rates, w_rot, p, i_scale, fz_ref)
        for row in range(2):
            J[row, col] = (fp[row] - fm[row]) / (2.0 * _DW)
    # (J^T J)^-1 = J^-1 J^-T: with A = J^T J symmetric 2 x 2.
    a = J[0, 0] * J[0, 0] + J[1, 0] * J[1, 0]
    b = J[0, 0] * J[0, 1] + J[1, 0] * J[1, 1]
    d = J[0, 1] * J[0, 1] + J[1, 1] * J[1, 1]
    det = a * d - b * b
    out = np.zeros((2, 2))
    s2 = sigma_b * sigma_b
    if det <= 0.0 or s2 * d / det > cap or s2 * a / det > cap:
        out[0, 0] = out[1, 1] = cap
        return out
    out[0, 0] = s2 * d / det
    out[1, 1] = s2 * a / det
    out[0, 1] = out[1, 0] = -s2 * b / det
    return out
