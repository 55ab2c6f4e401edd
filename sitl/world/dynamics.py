"""6-DOF rigid-body dynamics (paper Eq. 1-4) with motor speed dynamics, rotor inflow, RK4, and ground.

State vector ``x`` (N_STATE,), SI; rotor slots beyond the vehicle's rotor count stay zero:
  0:3   position, NED, m (ground at z = 0; altitude is -z)
  3:6   ground velocity, NED, m/s
  6:10  attitude quaternion [w, x, y, z], body FRD -> NED
  10:13 body rates [p, q, r], FRD, rad/s
  13:21 rotor speeds, rad/s (first-order lag to the command, clipped to limits), MAX_ROTORS slots
  21:29 induced velocity through each rotor disc, m/s (the blade-element truth's inflow states)

Forces: the vehicle's truth (:func:`vehicle.truth.truth_wrench`: blade-element rotors in the wind at
each hub, or the identified Eq. 46 at the airspeed V_a = R^T (V - W)), plus gravity. The paper writes
the translational equation in body axes (Eq. 3); integrating the NED velocity is the same motion and
keeps the quaternion the only rotating quantity.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from vehicle.frames import quat_to_dcm_into
from vehicle.params import MAX_ROTORS, P_G, P_IXX, P_IYY, P_IZZ, P_MASS, P_NROT, P_TAU, P_WMAX, P_WMIN
from vehicle.rotor_model import N_COEF
from vehicle.truth import truth_wrench

IX_POS, IX_VEL, IX_QUAT, IX_RATES, IX_ROTORS = 0, 3, 6, 10, 13
IX_INFLOW = IX_ROTORS + MAX_ROTORS
N_STATE = IX_INFLOW + MAX_ROTORS


class PhysicsWork(NamedTuple):
    """Scratch a physics tick works in, allocated once per physics loop (:func:`physics_work`), so a
    tick allocates nothing: the RK4 stages, the attitude matrix and the force model's buffers."""

    stages: np.ndarray  # (6, N_STATE): k1, k2, k3, k4, the stage's state, the new state
    R: np.ndarray  # (3, 3) body -> NED
    fm: np.ndarray  # (6,) forces N and moments N*m, FRD
    air: np.ndarray  # (3,) airspeed at the CG, FRD, m/s
    loads: np.ndarray  # (6,) one rotor's loads
    hubs: np.ndarray  # (MAX_ROTORS, 3) airspeed at each hub, FRD, m/s
    reg: np.ndarray  # (N_COEF,) the identified model's regressors
    accel: np.ndarray  # (3,) specific force of the stages after the first (discarded)


S_K1, S_K2, S_K3, S_K4, S_XT, S_XN = range(6)


@njit(cache=True)
def physics_work() -> PhysicsWork:
    """A fresh :class:`PhysicsWork` (once per physics loop, not per tick)."""
    return PhysicsWork(np.zeros((6, N_STATE)), np.zeros((3, 3)), np.zeros(6), np.zeros(3), np.zeros(6),
                       np.zeros((MAX_ROTORS, 3)), np.zeros(N_COEF), np.zeros(3))  # fmt: skip


@njit(cache=True)
def derivative(
    x: np.ndarray, w_cmd: np.ndarray, winds: np.ndarray, p: np.ndarray, out_accel_body: np.ndarray
) -> np.ndarray:
    """dx/dt for the state above (a new array; see :func:`derivative_into`)."""
    dx = np.zeros(N_STATE)
    derivative_into(x, w_cmd, winds, p, out_accel_body, dx, physics_work())
    return dx


@njit(cache=True, inline="always")
def derivative_into(
    x: np.ndarray, w_cmd: np.ndarray, winds: np.ndarray, p: np.ndarray, out_accel_body: np.ndarray,
    dx: np.ndarray, wk: PhysicsWork,
) -> None:  # fmt: skip
    """dx/dt for the state above into ``dx`` (N_STATE,). ``winds`` (1 + N, 3): air-mass velocity
    (NED, m/s) at the CG and at each hub. ``out_accel_body`` receives the specific force (FRD, m/s^2:
    non-gravitational force over mass), which is what an accelerometer measures. ``wk``: scratch."""
    R = wk.R
    quat_to_dcm_into(x[6:10], R)
    n = int(p[P_NROT])
    # Motor: first-order lag toward the (clipped) command; slots past the vehicle's rotors stay zero.
    tau = p[P_TAU]
    for i in range(MAX_ROTORS):
        dx[IX_ROTORS + i] = 0.0
        dx[IX_INFLOW + i] = 0.0
    for i in range(n):
        c = min(max(w_cmd[i], 0.0), p[P_WMAX])
        dx[IX_ROTORS + i] = (c - x[IX_ROTORS + i]) / tau
    fm = wk.fm
    truth_wrench(R, x[3:6], x[10:13], winds, x[IX_ROTORS:IX_ROTORS + MAX_ROTORS], dx[IX_ROTORS:IX_ROTORS + MAX_ROTORS],
                 x[IX_INFLOW:N_STATE], p, dx[IX_INFLOW:N_STATE], fm, wk.air, wk.hubs, wk.loads, wk.reg)  # fmt: skip
    m = p[P_MASS]
    fb0, fb1, fb2 = fm[0] / m, fm[1] / m, fm[2] / m
    out_accel_body[0] = fb0
    out_accel_body[1] = fb1
    out_accel_body[2] = fb2
    dx[0] = x[3]
    dx[1] = x[4]
    dx[2] = x[5]
    for i in range(3):
        dx[3 + i] = R[i, 0] * fb0 + R[i, 1] * fb1 + R[i, 2] * fb2
    dx[5] += p[P_G]
    # Quaternion kinematics (Eq. 1b): q_dot = 0.5 q * [0, omega].
    pr, qr, rr = x[10], x[11], x[12]
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    dx[6] = 0.5 * (-qx * pr - qy * qr - qz * rr)
    dx[7] = 0.5 * (qw * pr + qy * rr - qz * qr)
    dx[8] = 0.5 * (qw * qr - qx * rr + qz * pr)
    dx[9] = 0.5 * (qw * rr + qx * qr - qy * pr)
    # Euler's equation (Eq. 4), principal axes.
    ixx, iyy, izz = p[P_IXX], p[P_IYY], p[P_IZZ]
    dx[10] = (fm[3] - (izz - iyy) * qr * rr) / ixx
    dx[11] = (fm[4] - (ixx - izz) * pr * rr) / iyy
    dx[12] = (fm[5] - (iyy - ixx) * pr * qr) / izz


@njit(cache=True)
def rk4_step(
    x: np.ndarray,
    w_cmd: np.ndarray,
    winds: np.ndarray,
    p: np.ndarray,
    dt: float,
    on_ground: bool,
    accel_body: np.ndarray,
    wk: PhysicsWork,
) -> tuple[bool, float]:
    """Advance one fixed step with RK4 and resolve ground contact; the new state goes to
    ``wk.stages[S_XN]``.

    The winds and the rotor command are held over the step. Returns whether the vehicle rests on
    the ground, and the touchdown vertical speed (m/s, 0 if none). ``accel_body`` receives the
    specific force at the start of the step (the accelerometer truth), with the ground reaction
    included while resting. The stage sums are written element by element in the order numpy's
    expressions ``x + 0.5 * dt * k1`` ... evaluate them, so the result is the same bit for bit.
    """
    st = wk.stages
    k1, k2, k3, k4, xt, xn = st[S_K1], st[S_K2], st[S_K3], st[S_K4], st[S_XT], st[S_XN]
    # The four stages in one loop, so the force model is compiled (inlined) once: stage s evaluates the derivative
    # at x (s = 0) or at x + c k_s (c = dt/2, dt/2, dt), each sum formed as numpy's x + c * k would.
    half = 0.5 * dt
    for s in range(4):
        # The accelerometer truth is the first stage's specific force; the later stages' is discarded.
        derivative_into(x if s == 0 else xt, w_cmd, winds, p, accel_body if s == 0 else wk.accel, st[s], wk)
        if s == 0 and on_ground and k1[5] >= 0.0:
            return _rest_on_ground(x, w_cmd, p, dt, accel_body, wk)
        if s < 3:
            c = dt if s == 2 else half
            ks = st[s]
            for i in range(N_STATE):
                xt[i] = x[i] + c * ks[i]
    sixth = dt / 6.0
    for i in range(N_STATE):
        xn[i] = x[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    n = math.sqrt(xn[6] ** 2 + xn[7] ** 2 + xn[8] ** 2 + xn[9] ** 2)
    for i in range(6, 10):
        xn[i] /= n
    for i in range(IX_ROTORS, IX_ROTORS + MAX_ROTORS):
        xn[i] = min(max(xn[i], 0.0), p[P_WMAX])
    if xn[2] >= 0.0:
        # Touchdown (or still on the ground): stop on the ground, keep yaw, level.
        vz = xn[5]
        xn[2] = 0.0
        xn[3:6] = 0.0
        xn[10:13] = 0.0
        yaw = math.atan2(
            2 * (xn[6] * xn[9] + xn[7] * xn[8]), 1 - 2 * (xn[8] ** 2 + xn[9] ** 2)
        )
        xn[6] = math.cos(yaw / 2)
        xn[7] = 0.0
        xn[8] = 0.0
        xn[9] = math.sin(yaw / 2)
        return True, max(vz, 0.0)
    return False, 0.0


@njit(cache=True)
def _rest_on_ground(x: np.ndarray, w_cmd: np.ndarray, p: np.ndarray, dt: float, accel_body: np.ndarray,
                    wk: PhysicsWork) -> tuple[bool, float]:  # fmt: skip
    """A step resting on the ground (rotor thrust does not exceed weight) into ``wk.stages[S_XN]``: only the motors
    and their inflow evolve; the ground carries the rest, so the accelerometer reads -g along world down."""
    xn, k1 = wk.stages[S_XN], wk.stages[S_K1]
    xn[:] = x
    _rotor_exact(x[IX_ROTORS:IX_ROTORS + MAX_ROTORS], w_cmd, p, dt, xn[IX_ROTORS:IX_ROTORS + MAX_ROTORS])
    # The inflow (time constant >= 10 ms against the 2 ms step): one explicit Euler step.
    for i in range(IX_INFLOW, N_STATE):
        xn[i] = x[i] + dt * k1[i]
    xn[3:6] = 0.0
    xn[10:13] = 0.0
    R = wk.R
    quat_to_dcm_into(x[6:10], R)
    for i in range(3):
        accel_body[i] = -p[P_G] * R[2, i]
    return True, 0.0


@njit(cache=True)
def _rotor_exact(w: np.ndarray, w_cmd: np.ndarray, p: np.ndarray, dt: float, out: np.ndarray) -> None:
    """The rotor speeds (rad/s) after ``dt`` s of the first-order lag toward the clipped command, into ``out``."""
    a = math.exp(-dt / p[P_TAU])
    out[:] = 0.0
    for i in range(int(p[P_NROT])):
        c = min(max(w_cmd[i], 0.0), p[P_WMAX])
        out[i] = c + (w[i] - c) * a


@njit(cache=True)
def idle_speed(p: np.ndarray) -> float:
    """Armed idle rotor speed, rad/s."""
    return p[P_WMIN]
