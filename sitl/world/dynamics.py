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

import numpy as np
from numba import njit

from vehicle.frames import quat_to_dcm
from vehicle.params import MAX_ROTORS, P_G, P_IXX, P_IYY, P_IZZ, P_MASS, P_NROT, P_TAU, P_WMAX, P_WMIN
from vehicle.truth import truth_wrench

IX_POS, IX_VEL, IX_QUAT, IX_RATES, IX_ROTORS = 0, 3, 6, 10, 13
IX_INFLOW = IX_ROTORS + MAX_ROTORS
N_STATE = IX_INFLOW + MAX_ROTORS


@njit(cache=True)
def derivative(
    x: np.ndarray, w_cmd: np.ndarray, winds: np.ndarray, p: np.ndarray, out_accel_body: np.ndarray
) -> np.ndarray:
    """dx/dt for the state above. ``winds`` (1 + N, 3): air-mass velocity (NED, m/s) at the CG and at
    each hub. ``out_accel_body`` receives the specific force (FRD, m/s^2: non-gravitational force over
    mass), which is what an accelerometer measures."""
    dx = np.zeros(N_STATE)
    q = x[6:10]
    R = quat_to_dcm(q)
    rates = x[10:13]
    n = int(p[P_NROT])
    w_rot = x[IX_ROTORS:IX_ROTORS + MAX_ROTORS]
    # Motor: first-order lag toward the (clipped) command.
    tau = p[P_TAU]
    w_rot_dot = np.zeros(MAX_ROTORS)
    for i in range(n):
        c = min(max(w_cmd[i], 0.0), p[P_WMAX])
        w_rot_dot[i] = (c - w_rot[i]) / tau
    vi_dot = np.zeros(MAX_ROTORS)
    fm = truth_wrench(R, x[3:6], rates, winds, w_rot, w_rot_dot, x[IX_INFLOW:N_STATE], p, vi_dot)
    m = p[P_MASS]
    fb0, fb1, fb2 = fm[0] / m, fm[1] / m, fm[2] / m
    out_accel_body[0] = fb0
    out_accel_body[1] = fb1
    out_accel_body[2] = fb2
    dx[0:3] = x[3:6]
    for i in range(3):
        dx[3 + i] = R[i, 0] * fb0 + R[i, 1] * fb1 + R[i, 2] * fb2
    dx[5] += p[P_G]
    # Quaternion kinematics (Eq. 1b): q_dot = 0.5 q * [0, omega].
    pr, qr, rr = rates[0], rates[1], rates[2]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    dx[6] = 0.5 * (-qx * pr - qy * qr - qz * rr)
    dx[7] = 0.5 * (qw * pr + qy * rr - qz * qr)
    dx[8] = 0.5 * (qw * qr - qx * rr + qz * pr)
    dx[9] = 0.5 * (qw * rr + qx * qr - qy * pr)
    # Euler's equation (Eq. 4), principal axes.
    ixx, iyy, izz = p[P_IXX], p[P_IYY], p[P_IZZ]
    dx[10] = (fm[3] - (izz - iyy) * qr * rr) / ixx
    dx[11] = (fm[4] - (ixx - izz) * pr * rr) / iyy
    dx[12] = (fm[5] - (iyy - ixx) * pr * qr) / izz
    dx[IX_ROTORS:IX_ROTORS + MAX_ROTORS] = w_rot_dot
    dx[IX_INFLOW:N_STATE] = vi_dot
    return dx


@njit(cache=True)
def rk4_step(
    x: np.ndarray,
    w_cmd: np.ndarray,
    winds: np.ndarray,
    p: np.ndarray,
    dt: float,
    on_ground: bool,
    accel_body: np.ndarray,
) -> tuple[np.ndarray, bool, float]:
    """Advance one fixed step with RK4 and resolve ground contact.

    The winds and the rotor command are held over the step. Returns the new state, whether the
    vehicle rests on the ground, and the touchdown vertical speed (m/s, 0 if none).
    ``accel_body`` receives the specific force at the start of the step (the accelerometer
    truth), with the ground reaction included while resting.
    """
    k1 = derivative(x, w_cmd, winds, p, accel_body)
    scratch = np.empty(3)
    if on_ground and k1[5] >= 0.0:
        # Resting: rotor thrust does not exceed weight. Only the motors and their inflow evolve; the
        # ground carries the rest, so the accelerometer reads -g along world down.
        xn = x.copy()
        xn[IX_ROTORS:IX_ROTORS + MAX_ROTORS] = _rotor_exact(x[IX_ROTORS:IX_ROTORS + MAX_ROTORS], w_cmd, p, dt)
        # The inflow (time constant >= 10 ms against the 2 ms step): one explicit Euler step.
        xn[IX_INFLOW:N_STATE] = x[IX_INFLOW:N_STATE] + dt * k1[IX_INFLOW:N_STATE]
        xn[3:6] = 0.0
        xn[10:13] = 0.0
        R = quat_to_dcm(x[6:10])
        for i in range(3):
            accel_body[i] = -p[P_G] * R[2, i]
        return xn, True, 0.0
    k2 = derivative(x + 0.5 * dt * k1, w_cmd, winds, p, scratch)
    k3 = derivative(x + 0.5 * dt * k2, w_cmd, winds, p, scratch)
    k4 = derivative(x + dt * k3, w_cmd, winds, p, scratch)
    xn = x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    n = math.sqrt(xn[6] ** 2 + xn[7] ** 2 + xn[8] ** 2 + xn[9] ** 2)
    xn[6:10] /= n
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
        return xn, True, max(vz, 0.0)
    return xn, False, 0.0


@njit(cache=True)
def _rotor_exact(w: np.ndarray, w_cmd: np.ndarray, p: np.ndarray, dt: float) -> np.ndarray:
    a = math.exp(-dt / p[P_TAU])
    out = np.zeros(MAX_ROTORS)
    for i in range(int(p[P_NROT])):
        c = min(max(w_cmd[i], 0.0), p[P_WMAX])
        out[i] = c + (w[i] - c) * a
    return out


@njit(cache=True)
def idle_speed(p: np.ndarray) -> float:
    """Armed idle rotor speed, rad/s."""
    return p[P_WMIN]
