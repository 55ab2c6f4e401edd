"""The paper's identified rotor force and moment model (Eq. 40-46, Table 5), in SI.

This is the one implementation of the model: the simulator integrates it and the wind
estimator (issue 4) calls the same functions, so the two cannot drift apart.

Inputs (all SI, body frame FRD):
- ``v_air``: airspeed in body axes [u, v, w], m/s = R_BI (V_ground - wind_air_mass).
- ``rates``: body rates [p, q, r], rad/s.
- ``w_rot``: rotor speeds [Omega_1..4], rad/s (>= 0), rotor 1 front-right, 2 rear-right,
  3 rear-left, 4 front-left.
- ``w_rot_dot``: rotor accelerations, rad/s^2 (for the reaction torque).
Output: ``[X, Y, Z, L, M, N]``, the rotor forces (N) and moments about the CG (N*m) in FRD.

Notation (READING.md): delta = MIX @ Omega^2 (Eq. 40); the paper's "root delta" symbols are
MIX @ Omega, linear rotor speeds (Eq. 41), not arithmetic roots; ``u sign(u)`` is |u|.
The rotor gyroscopic term (J * body rate x rotor angular momentum) and the yaw reaction to
rotor acceleration follow the authors' public MATLAB model of this vehicle.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from vehicle.params import (
    MIX,
    P_B,
    P_COEF0,
    P_H,
    P_J,
    P_NROT,
    P_R,
    P_RHO,
    P_V0,
    P_VH_MAX,
    P_VZ_MAX,
    VehicleParams,
)

# Offsets of the coefficients (same order as vehicle.COEFFICIENT_NAMES).
(
    _CX_MU, _CX_MU2, _CX_MUZ, _CX_MUV,
    _CY_MU, _CY_MU2, _CY_MUZ, _CY_MUV,
    _CZ_T0, _CZ_TV, _CZ_TMU, _CZ_TZ, _CZ_TMU2,
    _CL_T0, _CL_TV, _CL_TMU, _CL_TZ, _CL_RMU,
    _CL_HMU, _CL_HMU2, _CL_HMUZ, _CL_HMUV, _CL_P_DT, _CL_P,
    _CM_T0, _CM_TV, _CM_TMU, _CM_TZ, _CM_RMU,
    _CM_HMU, _CM_HMU2, _CM_HMUZ, _CM_HMUV, _CM_Q_DT, _CM_Q,
    _CN_Q0, _CN_QV, _CN_QMU, _CN_QZ, _CN_HMU, _CN_R_DT, _CN_R,
) = range(P_COEF0, P_COEF0 + 42)  # fmt: skip


@njit(cache=True, fastmath=False)
def rotor_wrench(
    v_air: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, w_rot_dot: np.ndarray, p: np.ndarray
) -> np.ndarray:
    """Eq. 46 forces and moments, FRD body frame, SI. See the module docstring."""
    rho = p[P_RHO]
    R = p[P_R]
    b = p[P_B]
    h = p[P_H]
    v0 = p[P_V0]
    nr = p[P_NROT]
    J = p[P_J]
    u = v_air[0]
    v = v_air[1]
    w = v_air[2]
    pr = rates[0]
    qr = rates[1]
    rr = rates[2]
    o1, o2, o3, o4 = w_rot[0], w_rot[1], w_rot[2], w_rot[3]
    # Eq. 42 virtual actuators: squared (delta) and linear ("root delta") rotor speeds.
    s1, s2, s3, s4 = o1 * o1, o2 * o2, o3 * o3, o4 * o4
    dt = s1 + s2 + s3 + s4
    da = -s1 - s2 + s3 + s4
    de = s1 - s2 - s3 + s4
    dr = s1 - s2 + s3 - s4
    rt = o1 + o2 + o3 + o4
    ra = -o1 - o2 + o3 + o4
    re = o1 - o2 - o3 + o4
    rr_ = o1 - o2 + o3 - o4
    alpha_r = w_rot_dot[0] - w_rot_dot[1] + w_rot_dot[2] - w_rot_dot[3]

    k = rho * math.pi * R * R
    vh2 = u * u + v * v
    vh = math.sqrt(vh2)
    V2 = vh2 + w * w
    # Regressors leaving the identified domain saturate smoothly (tanh keeps the model
    # differentiable and informative for the estimator): see domain_* in the vehicle file.
    vhc = p[P_VH_MAX] * math.tanh(vh / p[P_VH_MAX])
    wc = p[P_VZ_MAX] * math.tanh(w / p[P_VZ_MAX])

    X = k * u * (p[_CX_MU] * R * rt + nr * (p[_CX_MU2] * abs(u) + p[_CX_MUZ] * wc + p[_CX_MUV] * v0))
    Y = k * v * (p[_CY_MU] * R * rt + nr * (p[_CY_MU2] * abs(v) + p[_CY_MUZ] * wc - p[_CY_MUV] * v0))
    Z = -k * (
        p[_CZ_T0] * R * R * dt
        + p[_CZ_TV] * R * v0 * rt
        + p[_CZ_TMU] * R * vh * rt
        + p[_CZ_TZ] * R * wc * rt
        + nr * p[_CZ_TMU2] * vh2
    )
    L = k * (
        b * R * (p[_CL_T0] * R * da - p[_CL_TV] * v0 * ra + p[_CL_TMU] * vhc * ra + p[_CL_TZ] * wc * ra)
        + p[_CL_RMU] * R * R * u * rr_
        + p[_CL_HMU] * h * R * v * rt
        + nr * h * v * (p[_CL_HMU2] * abs(v) - p[_CL_HMUZ] * wc + p[_CL_HMUV] * v0)
        + p[_CL_P_DT] * b * b * pr * rt
        + p[_CL_P] * b / v0 * v * v * pr
    )
    M = k * (
        b * R * (p[_CM_T0] * R * de + p[_CM_TV] * v0 * re + p[_CM_TMU] * vhc * re - p[_CM_TZ] * wc * re)
        + p[_CM_RMU] * R * R * v * rr_
        - p[_CM_HMU] * h * R * u * rt
        + nr * h * u * (p[_CM_HMU2] * abs(u) + p[_CM_HMUZ] * wc - p[_CM_HMUV] * v0)
        + p[_CM_Q_DT] * b * b * qr * rt
        + p[_CM_Q] * b / v0 * v * v * qr
    )
    N = k * (
        p[_CN_Q0] * R * R * R * dr
        + p[_CN_QV] * R * R * v0 * rr_
        + p[_CN_QMU] * R * R * vh * rr_
        + p[_CN_QZ] * R * R * wc * rr_
        + b * p[_CN_HMU] * (u * ra + v * re)
        + p[_CN_R_DT] * b * b * rr * rt
        + p[_CN_R] * b / v0 * V2 * rr
    )
    # Rotor gyroscopic moment: rotors 1 and 3 spin about -z_b (counter-clockwise from above),
    # so the rotor angular momentum is -J * rr_ * z_b and the moment on the body is
    # -omega x h_rotor = J * rr_ * [q, -p, 0]; accelerating rotors 1 and 3 yaws the body +z.
    L += J * rr_ * qr
    M -= J * rr_ * pr
    N += J * alpha_r
    out = np.empty(6)
    out[0] = X
    out[1] = Y
    out[2] = Z
    out[3] = L
    out[4] = M
    out[5] = N
    return out


def wrench(
    params: VehicleParams,
    v_air: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    w_rot_dot: np.ndarray | None = None,
) -> np.ndarray:
    """Convenience wrapper of :func:`rotor_wrench` for Python callers (SI, FRD)."""
    return rotor_wrench(
        np.asarray(v_air, dtype=float),
        np.asarray(rates, dtype=float),
        np.asarray(w_rot, dtype=float),
        np.zeros(4) if w_rot_dot is None else np.asarray(w_rot_dot, dtype=float),
        params.as_array(),
    )


def hover_rotor_speed(params: VehicleParams) -> float:
    """Equal rotor speed (rad/s) whose Eq. 46c thrust balances the weight at zero airspeed.

    Solves rho pi R^2 (C_ZT0 R^2 4 W^2 + C_ZTv R v0 4 W) = m g for W.
    """
    p = params.as_array()
    k = p[P_RHO] * math.pi * p[P_R] ** 2
    a = 4.0 * k * p[_CZ_T0] * p[P_R] ** 2
    bq = 4.0 * k * p[_CZ_TV] * p[P_R] * p[P_V0]
    c = -params.mass_kg * params.gravity_m_s2
    return float((-bq + math.sqrt(bq * bq - 4 * a * c)) / (2 * a))


def mixing_inverse() -> np.ndarray:
    """Inverse of the Eq. 42 mixing matrix (its rows are orthogonal: MIX^-1 = MIX^T / 4)."""
    return MIX.T / 4.0
