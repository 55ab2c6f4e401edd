"""A first-principles rotor: blade-element theory with momentum inflow and rigid flapping (paper Eqs. 5-36).

This is the world's truth when a vehicle file says ``truth = "bet"``: the paper's truth was a
blade-element simulation, and the wind estimator's model (Eq. 46, :mod:`vehicle.rotor_model`) is
*identified* from flights of it, never the same equations.

One rotor, as the paper develops it (after Johnson, "Helicopter Theory", ch. 5):

- the blade section sees ``u_T = r + mu sin(psi)`` and ``u_P = lambda + r beta' + mu beta cos(psi)``
  plus the shaft's pitch and roll rates (Eqs. 14-15); lift ``F_z = a c / 2 (u_T^2 theta - u_P u_T)``,
  in-plane force ``F_x = a c / 2 (u_P u_T theta - u_P^2) + c C_d / 2 u_T^2``, radial ``-beta F_z``
  (Eqs. 19-21); linear twist ``theta = theta_0 + theta_tw r``;
- thrust, H-force, side force and torque are Eqs. 22-24 integrated over radius and azimuth in
  closed form, keeping every term to second order in the small quantities (flap angles, body rates
  over rotor speed); the integration was done symbolically and is checked against numerical
  quadrature of the same element loads in ``tests/test_bet.py``;
- flapping ``beta = beta_0 + beta_1c cos(psi) + beta_1s sin(psi)`` (Eq. 13) about a central hinge with
  a spring ``K_beta`` (Eqs. 32-34): the first-harmonic balance of the flap equation
  ``beta'' + lambda_beta^2 beta - 2 (p cos(psi) + q sin(psi)) / Omega = gamma M_aero`` solved each
  evaluation (quasi-steady), with ``lambda_beta^2 = 1 + K_beta / (I_b Omega^2)`` and the Lock
  number ``gamma = rho a c R^4 / I_b``; the hub receives the spring moment ``K_beta beta`` about the
  flap axis, which is how a stiff propeller pitches and rolls the vehicle in edgewise flight;
- inflow: uniform, ``lambda = mu_z + v_i / (Omega R)``, with the induced velocity ``v_i`` a state that
  relaxes to Glauert's momentum-theory value ``C_T / (2 sqrt(mu^2 + lambda^2))`` (Eq. 10-11) with
  the Pitt-Peters uniform-mode time constant ``(8 / 3 pi) / (2 Omega sqrt(mu^2 + lambda^2))`` (14 ms
  at the paper's hover): in steady flight ``v_i`` is the momentum-theory solution in climb, descent
  and forward flight. In the vortex-ring region (descent near the induced velocity) momentum
  theory has no solution; the induced velocity is bounded there at 1.7 times its hover value
  (the peak measured in that region), and the fluctuating thrust of a vortex ring is not modelled.

Frames. The loads are computed in the rotor's wind frame ``W`` (x along the hub's in-plane motion
through the air, y to the left of it, z up the shaft) for a rotor turning counter-clockwise seen
from above; a clockwise rotor is its mirror image (y mirrored), so one set of equations serves both.
Inputs and outputs are in the body frame FRD, SI. Not modelled: ground effect, tip loss, root
cut-out, reverse flow (valid for advance ratios below about 0.5), blade stall, rotor-rotor
interference.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Pitt-Peters apparent-mass coefficient of the uniform inflow mode, 8 / (3 pi).
INFLOW_MASS = 8.0 / (3.0 * math.pi)
#: Bound on the induced velocity in the vortex-ring region, as a multiple of its momentum value at
#: the same thrust in hover (the denominator sqrt(mu^2 + lambda^2) is kept >= lambda_h / VRS_PEAK).
VRS_PEAK = 1.7
#: Below this rotor speed (rad/s) a rotor makes no aerodynamic load.
OMEGA_STOPPED = 1.0

# Indices of a rotor's blade parameters inside the flat array (see vehicle.params, P_BLADE0).
B_NB, B_CHORD, B_A, B_TH0, B_TTW, B_CD, B_IB, B_KB, B_JHUB, B_R = range(10)
N_BLADE = 10


@njit(cache=True, inline="always")
def _flapping(
    mu: float, lam: float, pb: float, qb: float, th0: float, ttw: float, gam: float, lb2: float
) -> tuple[float, float, float]:
    """Quasi-steady first-harmonic flapping (rad) in the wind frame: the harmonic balance of the flap
    equation, ``A beta = b`` (3 x 3, solved by Cramer's rule)."""
    a00 = lb2
    a10 = gam * mu / 6.0
    a11 = lb2 - 1.0
    a12 = gam * (mu * mu / 16.0 + 0.125)
    a21 = gam * (mu * mu / 16.0 - 0.125)
    a22 = lb2 - 1.0
    r0 = gam * (th0 / 8.0 + ttw / 10.0 - lam / 6.0 + mu * mu * (th0 / 8.0 + ttw / 12.0) + mu * pb / 12.0)
    r1 = 2.0 * pb - gam * qb / 8.0
    r2 = 2.0 * qb + gam * (mu * (th0 / 3.0 + ttw / 4.0 - lam / 4.0) + pb / 8.0)
    b0 = r0 / a00
    # the lower 2 x 2 block, with the coning moved to the right-hand side
    s1 = r1 - a10 * b0
    det = a11 * a22 - a12 * a21
    b1c = (s1 * a22 - a12 * r2) / det
    b1s = (a11 * r2 - a21 * s1) / det
    return b0, b1c, b1s


@njit(cache=True, inline="always")
def _thrust(mu: float, lam: float, pb: float, qb: float, th0: float, ttw: float,
            b0: float, c: float, s: float) -> float:  # fmt: skip
    """Thrust of one blade along the shaft over ``rho a c (Omega R)^2 R`` (Eqs. 22, 27; c, s = beta_1c,
    beta_1s)."""
    m2 = mu * mu
    tt = th0 + 0.75 * ttw  # th0 + 3/4 ttw appears in every flap-squared term
    f = th0 / 6.0 + ttw / 8.0 - lam / 4.0 + m2 * (th0 / 4.0 + ttw / 8.0) + mu * pb / 8.0
    f += b0 * mu * qb * (th0 / 4.0 + ttw / 6.0)
    f += (c * pb + s * qb) * (4.0 * th0 + 3.0 * ttw - 3.0 * lam) / 24.0
    f += b0 * b0 * (lam / 4.0 - tt / 4.0 - m2 * (th0 / 8.0 + ttw / 16.0))
    f += b0 * s * mu * (lam / 4.0 - th0 / 2.0 - ttw / 3.0)
    f += c * c * (lam / 8.0 - tt / 8.0 - m2 * (th0 / 32.0 + ttw / 64.0))
    f += s * s * (lam / 8.0 - tt / 8.0 - m2 * (3.0 * th0 / 32.0 + 3.0 * ttw / 64.0))
    return f


@njit(cache=True, inline="always")
def _inplane(mu: float, lam: float, pb: float, qb: float, th0: float, ttw: float, cda: float,
             b0: float, c: float, s: float) -> tuple[float, float, float]:  # fmt: skip
    """In-plane forces (x along the motion, y left) and torque (opposing the rotation) of one blade,
    over ``rho a c (Omega R)^2 R`` and ``... R^2`` (Eqs. 23-24, 28-29; cda = C_d / a)."""
    m2 = mu * mu
    lt = lam * th0 / 8.0 + lam * ttw / 12.0  # recurring lambda (theta_0 / 8 + theta_tw / 12)
    fx = -(cda * mu + lam * mu * (th0 + ttw / 2.0) + lam * pb - pb * (th0 / 3.0 + ttw / 4.0)) / 4.0
    fx -= b0 * qb * (cda / 6.0 + lt + 1.0 / 12.0)
    fx -= c * (6.0 * cda * mu * pb + 36.0 * lam + 3.0 * mu * pb - 16.0 * th0 - 12.0 * ttw) / 96.0
    fx -= s * mu * qb * (6.0 * cda - 1.0) / 32.0
    fx += b0 * b0 * mu * (cda - 1.0) / 8.0 + b0 * s * (cda / 6.0 + lt - 1.0 / 12.0)
    fx += c * c * mu * (cda - 4.0) / 32.0 + s * s * 3.0 * cda * mu / 32.0
    fy = -qb * (lam - th0 / 3.0 - ttw / 4.0) / 4.0
    fy += b0 * (cda * pb / 6.0 - 0.75 * lam * mu + lt * pb + mu * (3.0 * th0 / 8.0 + ttw / 4.0) + pb / 12.0)
    fy += c * mu * qb * (2.0 * cda - 7.0) / 32.0
    fy += s * (6.0 * cda * mu * pb - 36.0 * lam + m2 * (24.0 * th0 + 12.0 * ttw) + 15.0 * mu * pb
               + 16.0 * th0 + 12.0 * ttw) / 96.0  # fmt: skip
    fy -= b0 * c * (cda / 6.0 + lt + m2 / 2.0 - 1.0 / 12.0) + c * s * mu * (cda + 2.0) / 16.0
    lq = lam * (th0 / 12.0 + ttw / 16.0)  # recurring lambda (theta_0 / 12 + theta_tw / 16)
    tq = cda * (1.0 + m2) / 8.0 - lam * lam / 4.0 + lam * (th0 / 6.0 + ttw / 8.0)
    tq -= mu * pb * (th0 / 12.0 + ttw / 16.0) + (pb * pb + qb * qb) / 16.0
    tq += b0 * mu * qb * (cda - 1.0) / 6.0
    tq += c * (cda * pb / 8.0 - lam * mu / 4.0 + lq * pb - pb / 8.0) + s * qb * (cda / 8.0 + lq - 1.0 / 8.0)
    tq -= b0 * b0 * (cda / 8.0 + lq + m2 / 8.0) + b0 * s * mu * (cda + 1.0) / 6.0
    tq -= c * c * (cda / 16.0 + lq / 2.0 + 3.0 * m2 / 32.0 + 1.0 / 16.0)
    tq -= s * s * (cda / 16.0 + lq / 2.0 + m2 / 32.0 + 1.0 / 16.0)
    return fx, fy, tq


@njit(cache=True, inline="always")
def rotor_loads(
    v_hub: np.ndarray, rates: np.ndarray, omega: float, spin: float, v_i: float, rho: float,
    bp: np.ndarray | tuple[float, ...], out: np.ndarray,
) -> float:  # fmt: skip
    """Loads of one rotor and the rate of change of its induced velocity.

    Args:
        v_hub: velocity of the hub through the air, body FRD, m/s (Eq. 5: airspeed plus rates x arm).
        rates: body rates FRD, rad/s (the shaft's pitch and roll rates drive the flapping).
        omega: rotor speed, rad/s (>= 0). spin: +1 counter-clockwise seen from above, -1 clockwise.
        v_i: induced velocity through the disc (m/s, positive down the shaft): the inflow state.
        rho: air density, kg/m^3. bp: the rotor's blade parameters (``B_*`` indices; an array or a tuple).
        out: receives force (N) and moment about the hub (N*m), body FRD, ``[Fx, Fy, Fz, L, M, N]``;
            the moment holds the hinge-spring moments and the rotor torque, not the arm's r x F.
    Returns: d v_i / dt, m/s^2.
    """
    R = bp[B_R]
    if omega < OMEGA_STOPPED:
        out[:] = 0.0
        return -v_i / 0.1
    # Body FRD -> rotor frame (x forward, z up the shaft; y left for a CCW rotor, right for a CW one,
    # the mirror image). Vectors map by diag(1, -spin, -1), pseudo-vectors (rates, moments) by
    # det * diag(...) = diag(spin, -1, spin).
    vx, vy, vz = v_hub[0], -spin * v_hub[1], -v_hub[2]
    px, qy = spin * rates[0], -rates[1]
    vip = math.sqrt(vx * vx + vy * vy)
    if vip > 1e-9:
        cw, sw = vx / vip, vy / vip
    else:
        cw, sw = 1.0, 0.0
    wr = omega * R
    mu = vip / wr
    lam = vz / wr + v_i / wr  # climb (up) plus induced inflow, both through the disc
    pb = (cw * px + sw * qy) / omega  # rates in the wind frame, over Omega
    qb = (-sw * px + cw * qy) / omega
    nb, ch, a = bp[B_NB], bp[B_CHORD], bp[B_A]
    th0, ttw, ib = bp[B_TH0], bp[B_TTW], bp[B_IB]
    gam = rho * a * ch * R**4 / ib
    lb2 = 1.0 + bp[B_KB] / (ib * omega * omega)
    b0, b1c, b1s = _flapping(mu, lam, pb, qb, th0, ttw, gam, lb2)
    fz = _thrust(mu, lam, pb, qb, th0, ttw, b0, b1c, b1s)
    fx, fy, tq = _inplane(mu, lam, pb, qb, th0, ttw, bp[B_CD] / a, b0, b1c, b1s)
    # Inflow: Glauert's momentum value at this thrust, approached with the Pitt-Peters lag.
    sigma_a = nb * ch * a / (math.pi * R)
    ct = sigma_a * fz
    lam_h = math.sqrt(0.5 * abs(ct))
    vt = max(math.sqrt(mu * mu + lam * lam), lam_h / VRS_PEAK, 1e-4)
    vi_dot = (wr * ct / (2.0 * vt) - v_i) * (2.0 * omega * vt / INFLOW_MASS)
    # Dimensional loads in the wind frame; the spring moment K beta about each blade's flap axis,
    # averaged over a revolution: n_b K / 2 (-beta_1s, beta_1c, 0).
    fs = nb * rho * a * ch * wr * wr * R
    kh = 0.5 * nb * bp[B_KB]
    Fx, Fy, Fz = fs * fx, fs * fy, fs * fz
    Mx, My, Mz = -kh * b1s, kh * b1c, -fs * R * tq
    # Wind frame -> rotor frame (rotate by the in-plane direction) -> body FRD.
    rx, ry = cw * Fx - sw * Fy, sw * Fx + cw * Fy
    mx, my = cw * Mx - sw * My, sw * Mx + cw * My
    out[0] = rx
    out[1] = -spin * ry
    out[2] = -Fz
    out[3] = spin * mx
    out[4] = -my
    out[5] = -spin * Mz
    return vi_dot
