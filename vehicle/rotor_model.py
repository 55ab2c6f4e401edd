"""The paper's identified rotor force and moment model (Eq. 40-46), in SI: the wind estimator's model.

One implementation, as regressors: :func:`model_regressors` evaluates every candidate term of Eq. 46
(the coefficient's regressor, without the coefficient), :func:`rotor_wrench` sums coefficient times
regressor per axis, and the system identification (``identify/``) fits the coefficients on the very
same regressors. The world flies this model only when a vehicle file says ``truth = "model"``.

Inputs (all SI, body frame FRD):
- ``v_air``: airspeed in body axes [u, v, w], m/s = R_BI (V_ground - wind_air_mass).
- ``rates``: body rates [p, q, r], rad/s.
- ``w_rot``: rotor speeds, rad/s (>= 0), in the vehicle's rotor order (the quad X: 1 front-right,
  2 rear-right, 3 rear-left, 4 front-left).
- ``w_rot_dot``: rotor accelerations, rad/s^2 (for the reaction torque).
Output: ``[X, Y, Z, L, M, N]``, the rotor forces (N) and moments about the CG (N*m) in FRD.

Notation (READING.md): delta = M_ix @ Omega^2 (Eq. 40); the paper's "root delta" symbols are
M_ix @ Omega, linear rotor speeds (Eq. 41), not arithmetic roots; ``u sign(u)`` is |u|. M_ix is the
vehicle's (:func:`vehicle.params.mixing_matrix`; Eq. 42 for the quad X), so a hexarotor has the same
model structure. The rotor gyroscopic term (J * body rate x rotor angular momentum) and the yaw
reaction to rotor acceleration follow the authors' public MATLAB model of this vehicle; they are
known terms (J from the vehicle file), not identified.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from vehicle.params import (
    COEFFICIENT_NAMES,
    MAX_ROTORS,
    P_B,
    P_COEF0,
    P_H,
    P_J,
    P_MIX0,
    P_NROT,
    P_R,
    P_RHO,
    P_ROT0,
    P_V0,
    P_VH_MAX,
    P_VZ_MAX,
    VehicleParams,
)

N_COEF = len(COEFFICIENT_NAMES)
#: Axis (0..5 = X, Y, Z, L, M, N) of every coefficient, from its name.
AXIS_OF = np.array(["XYZlmn".index(name[2]) for name in COEFFICIENT_NAMES], dtype=np.int64)
AXIS_NAMES = ("x", "y", "z", "l", "m", "n")

# Offsets of the coefficients (same order as vehicle.COEFFICIENT_NAMES), relative to P_COEF0.
(
    _CX_MU, _CX_MU2, _CX_MUZ, _CX_MUV,
    _CY_MU, _CY_MU2, _CY_MUZ, _CY_MUV,
    _CZ_T0, _CZ_TV, _CZ_TMU, _CZ_TZ, _CZ_TMU2,
    _CL_T0, _CL_TV, _CL_TMU, _CL_TZ, _CL_RMU,
    _CL_HMU, _CL_HMU2, _CL_HMUZ, _CL_HMUV, _CL_P_DT, _CL_P,
    _CM_T0, _CM_TV, _CM_TMU, _CM_TZ, _CM_RMU,
    _CM_HMU, _CM_HMU2, _CM_HMUZ, _CM_HMUV, _CM_Q_DT, _CM_Q,
    _CN_Q0, _CN_QV, _CN_QMU, _CN_QZ, _CN_HMU, _CN_R_DT, _CN_R,
    _CX_Q_DT, _CY_P_DT, _CX_D, _CY_D, _CZ_D, _CZ_TI, _CZ_TIZ,
) = range(N_COEF)  # fmt: skip


@njit(cache=True)
def model_regressors(v_air: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
    """Every Eq. 46 regressor (N or N*m per unit coefficient) into ``out`` (N_COEF,), in the order of
    ``COEFFICIENT_NAMES``. Airspeeds leaving the identified domain saturate smoothly (tanh; the vehicle
    file's ``domain_*``): the model stays differentiable and informative for the estimator."""
    rho, R, b, h, v0, nr = p[P_RHO], p[P_R], p[P_B], p[P_H], p[P_V0], p[P_NROT]
    u, v, w = v_air[0], v_air[1], v_air[2]
    pr, qr, rr = rates[0], rates[1], rates[2]
    # Eq. 40-41 virtual actuators: squared (delta) and linear ("root delta") rotor speeds.
    dt = da = de = dr = rt = ra = re = ry = 0.0
    for i in range(int(nr)):
        o = w_rot[i]
        s = o * o
        m0, m1 = p[P_MIX0 + i], p[P_MIX0 + MAX_ROTORS + i]
        m2, m3 = p[P_MIX0 + 2 * MAX_ROTORS + i], p[P_MIX0 + 3 * MAX_ROTORS + i]
        dt += m0 * s
        da += m1 * s
        de += m2 * s
        dr += m3 * s
        rt += m0 * o
        ra += m1 * o
        re += m2 * o
        ry += m3 * o
    k = rho * math.pi * R * R
    vh2 = u * u + v * v
    vh = math.sqrt(vh2)
    V2 = vh2 + w * w
    vhc = p[P_VH_MAX] * math.tanh(vh / p[P_VH_MAX])
    wc = p[P_VZ_MAX] * math.tanh(w / p[P_VZ_MAX])
    out[_CX_MU] = k * u * R * rt  # Eq. 46a
    out[_CX_MU2] = k * u * nr * abs(u)
    out[_CX_MUZ] = k * u * nr * wc
    out[_CX_MUV] = k * u * nr * v0
    out[_CY_MU] = k * v * R * rt  # Eq. 46b
    out[_CY_MU2] = k * v * nr * abs(v)
    out[_CY_MUZ] = k * v * nr * wc
    out[_CY_MUV] = -k * v * nr * v0
    out[_CZ_T0] = -k * R * R * dt  # Eq. 46c
    out[_CZ_TV] = -k * R * v0 * rt
    out[_CZ_TMU] = -k * R * vh * rt
    out[_CZ_TZ] = -k * R * wc * rt
    out[_CZ_TMU2] = -k * nr * vh2
    out[_CL_T0] = k * b * R * R * da  # Eq. 46d
    out[_CL_TV] = -k * b * R * v0 * ra
    out[_CL_TMU] = k * b * R * vhc * ra
    out[_CL_TZ] = k * b * R * wc * ra
    out[_CL_RMU] = k * R * R * u * ry
    out[_CL_HMU] = k * h * R * v * rt
    out[_CL_HMU2] = k * nr * h * v * abs(v)
    out[_CL_HMUZ] = -k * nr * h * v * wc
    out[_CL_HMUV] = k * nr * h * v * v0
    out[_CL_P_DT] = k * b * b * pr * rt
    out[_CL_P] = k * b / v0 * v * v * pr
    out[_CM_T0] = k * b * R * R * de  # Eq. 46e
    out[_CM_TV] = k * b * R * v0 * re
    out[_CM_TMU] = k * b * R * vhc * re
    out[_CM_TZ] = -k * b * R * wc * re
    out[_CM_RMU] = k * R * R * v * ry
    out[_CM_HMU] = -k * h * R * u * rt
    out[_CM_HMU2] = k * nr * h * u * abs(u)
    out[_CM_HMUZ] = k * nr * h * u * wc
    out[_CM_HMUV] = -k * nr * h * u * v0
    out[_CM_Q_DT] = k * b * b * qr * rt
    out[_CM_Q] = k * b / v0 * v * v * qr
    out[_CN_Q0] = k * R * R * R * dr  # Eq. 46f
    out[_CN_QV] = k * R * R * v0 * ry
    out[_CN_QMU] = k * R * R * vh * ry
    out[_CN_QZ] = k * R * R * wc * ry
    out[_CN_HMU] = k * b * (u * ra + v * re)
    out[_CN_R_DT] = k * b * b * rr * rt
    out[_CN_R] = k * b / v0 * V2 * rr
    # Assumption 1 (the body rates' share of the local advance ratios) on the forces.
    out[_CX_Q_DT] = k * R * R * qr * rt
    out[_CY_P_DT] = k * R * R * pr * rt
    # The fuselage's parasitic drag, proportional to the airspeed squared (the coefficient is
    # -C_D A / (2 pi R^2) per axis).
    V = math.sqrt(V2)
    out[_CX_D] = k * u * V
    out[_CY_D] = k * v * V
    out[_CZ_D] = k * w * V
    # The induced velocity of a rotor in edgewise flight, Eq. 12: v^2 = -V^2/2 + sqrt(V^4/4 + v0^4)
    # (v0 at hover), which Eq. 37 linearizes; over a wide airspeed range the thrust needs it whole.
    vi = math.sqrt(-0.5 * vh2 + math.sqrt(0.25 * vh2 * vh2 + v0**4))
    out[_CZ_TI] = -k * R * vi * rt
    out[_CZ_TIZ] = -k * R * wc * rt * vi / v0


@njit(cache=True)
def known_moments(rates: np.ndarray, w_rot: np.ndarray, w_rot_dot: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
    """The terms of the moments that are not identified (rotor inertia J from the vehicle file), added to
    ``out[3:6]``: the rotors' gyroscopic moment and their reaction to rotor acceleration. Counter-clockwise
    rotors (spin +1) spin about -z_b: angular momentum -J h z_b with h = sum(spin w), moment on the body
    -omega x (-J h z_b) = J h [q, -p, 0]; accelerating them yaws the body +z_b."""
    h = 0.0
    alpha = 0.0
    for i in range(int(p[P_NROT])):
        spin = p[P_ROT0 + 4 * i + 3]
        h += spin * w_rot[i]
        alpha += spin * w_rot_dot[i]
    J = p[P_J]
    out[3] += J * h * rates[1]
    out[4] -= J * h * rates[0]
    out[5] += J * alpha


@njit(cache=True)
def rotor_wrench(
    v_air: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, w_rot_dot: np.ndarray, p: np.ndarray
) -> np.ndarray:
    """Eq. 46 forces and moments, FRD body frame, SI. See the module docstring."""
    out = np.empty(6)
    rotor_wrench_into(v_air, rates, w_rot, w_rot_dot, p, np.empty(N_COEF), out)
    return out


@njit(cache=True, inline="always")
def rotor_wrench_into(
    v_air: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, w_rot_dot: np.ndarray, p: np.ndarray, reg: np.ndarray,
    out: np.ndarray,
) -> None:  # fmt: skip
    """:func:`rotor_wrench` into ``out`` (6,: [X, Y, Z] N, [L, M, N] N*m, FRD) with ``reg`` (N_COEF,) as
    scratch for the regressors: no allocation, for the estimator's loops over sigma points."""
    model_regressors(v_air, rates, w_rot, p, reg)
    out[:] = 0.0
    for i in range(N_COEF):
        c = p[P_COEF0 + i]
        if c != 0.0:
            out[AXIS_OF[i]] += c * reg[i]
    known_moments(rates, w_rot, w_rot_dot, p, out)


def wrench(
    params: VehicleParams,
    v_air: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    w_rot_dot: np.ndarray | None = None,
) -> np.ndarray:
    """Convenience wrapper of :func:`rotor_wrench` for Python callers (SI, FRD; ``w_rot`` (N,))."""
    w = np.zeros(MAX_ROTORS)
    w[: params.n_rotors] = np.asarray(w_rot, dtype=float)
    wd = np.zeros(MAX_ROTORS)
    if w_rot_dot is not None:
        wd[: params.n_rotors] = np.asarray(w_rot_dot, dtype=float)
    return rotor_wrench(np.asarray(v_air, dtype=float), np.asarray(rates, dtype=float), w, wd, params.as_array())


def static_thrust_curve(params: VehicleParams) -> tuple[float, float]:
    """The *model's* thrust of one rotor at zero airspeed, ``T = a w^2 + b w`` (N; a per (rad/s)^2, b per
    rad/s): Eq. 46's Z with every rotor at one speed (its zero-airspeed terms are these two powers)."""
    n = params.n_rotors
    p = params.as_array()
    zero = np.zeros(3)
    t1 = -rotor_wrench(zero, zero, np.full(MAX_ROTORS, 100.0), np.zeros(MAX_ROTORS), p)[2] / n
    t2 = -rotor_wrench(zero, zero, np.full(MAX_ROTORS, 200.0), np.zeros(MAX_ROTORS), p)[2] / n
    a = (t2 - 2.0 * t1) / (200.0**2 - 2.0 * 100.0**2)
    b = (t1 - a * 100.0**2) / 100.0
    return float(a), float(b)


def hover_rotor_speed(params: VehicleParams) -> float:
    """Equal rotor speed (rad/s) whose *model* (Eq. 46) thrust balances the weight at zero airspeed (the
    truth's hover speed is ``params.control["hover_speed"]``)."""
    a, b = static_thrust_curve(params)
    if a <= 0.0:
        raise ValueError(f"vehicle {params.name}: the model has no thrust at zero airspeed (C_Z_T0 = "
                         f"{params.coefficients.get('C_Z_T0')})")
    weight = params.mass_kg * params.gravity_m_s2 / params.n_rotors
    return float((-b + math.sqrt(b * b + 4.0 * a * weight)) / (2.0 * a))


def mixing_inverse() -> np.ndarray:
    """Inverse of the Eq. 42 mixing matrix (its rows are orthogonal: MIX^-1 = MIX^T / 4)."""
    from vehicle.params import MIX

    return MIX.T / 4.0


@njit(cache=True)
def regressor_matrix(v_air: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, p: np.ndarray) -> np.ndarray:
    """:func:`model_regressors` at every sample: (n, N_COEF) from airspeeds (n, 3), rates (n, 3) and rotor
    speeds (n, >= N): the system identification's regressor matrix, by the estimator's own code."""
    n = v_air.shape[0]
    out = np.empty((n, N_COEF))
    w = np.zeros(MAX_ROTORS)
    k = min(w_rot.shape[1], MAX_ROTORS)
    for i in range(n):
        w[:k] = w_rot[i, :k]
        model_regressors(v_air[i], rates[i], w, p, out[i])
    return out


@njit(cache=True)
def known_moment_matrix(rates: np.ndarray, w_rot: np.ndarray, w_rot_dot: np.ndarray, p: np.ndarray) -> np.ndarray:
    """:func:`known_moments` at every sample: (n, 3) moments (N*m, FRD) the model does not identify."""
    n = rates.shape[0]
    out = np.zeros((n, 3))
    w = np.zeros(MAX_ROTORS)
    wd = np.zeros(MAX_ROTORS)
    k = min(w_rot.shape[1], MAX_ROTORS)
    tmp = np.zeros(6)
    for i in range(n):
        w[:k] = w_rot[i, :k]
        wd[:k] = w_rot_dot[i, :k]
        tmp[:] = 0.0
        known_moments(rates[i], w, wd, p, tmp)
        out[i] = tmp[3:6]
    return out
