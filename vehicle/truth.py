"""The world's force model, chosen per vehicle file (``truth``), and what an autopilot knows of it.

:func:`truth_wrench` is what the rigid body integrates (:mod:`sitl.world.dynamics`):

- ``bet``: every rotor by blade-element theory (:func:`vehicle.bet.rotor_loads`) at its own hub, in
  the wind at that hub (Eq. 5: the airspeed, the body rates times the arm, the local wind), the arm's
  ``r x F``, the gyroscopic moment of the non-flapping rotating parts, the rotors' reaction torque to
  their acceleration, and the fuselage's parasitic drag ``-1/2 rho C_D A |V| V`` per body axis;
- ``sih``: PX4 SIH's rotors (thrust and torque proportional to the command, linear drag);
- ``model``: the identified Eq. 46 (:func:`vehicle.rotor_model.rotor_wrench`), the wind at the CG.

:func:`with_control_figures` derives, from the truth, the few numbers a flight controller is tuned
with (the built-in autopilot's allocation, PX4's parameter file): each rotor's static thrust curve,
its torque-to-thrust ratio, the vehicle's rate damping and its hover rotor speed.

Units SI; FRD body; winds are air-mass velocities in NED.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numba import njit

from vehicle.bet import rotor_loads
from vehicle.params import (
    MAX_ROTORS,
    P_BLADE0,
    P_CDA_X,
    P_CDA_Y,
    P_CDA_Z,
    P_J,
    P_JHUB,
    P_NROT,
    P_RHO,
    P_ROT0,
    P_SIH_KDV,
    P_SIH_KDW,
    P_SIH_QMAX,
    P_SIH_TMAX,
    P_TRUTH,
    P_WMAX,
    TRUTH_BET,
    TRUTH_SIH,
    VehicleParams,
)
from vehicle.rotor_model import N_COEF, rotor_wrench_into


@njit(cache=True, inline="always")
def hub_airspeeds(R: np.ndarray, vel: np.ndarray, rates: np.ndarray, hub_winds: np.ndarray, p: np.ndarray,
                  out: np.ndarray) -> None:  # fmt: skip
    """Velocity of every hub through the air, body FRD (N, 3) m/s: R^T (V - W_hub) + omega x r (Eq. 5).
    ``R`` body -> NED; ``vel`` NED m/s; ``rates`` FRD rad/s; ``hub_winds`` (N, 3) air-mass velocity NED."""
    n = int(p[P_NROT])
    for i in range(n):
        rx, ry, rz = p[P_ROT0 + 4 * i], p[P_ROT0 + 4 * i + 1], p[P_ROT0 + 4 * i + 2]
        d0, d1, d2 = vel[0] - hub_winds[i, 0], vel[1] - hub_winds[i, 1], vel[2] - hub_winds[i, 2]
        for k in range(3):
            out[i, k] = R[0, k] * d0 + R[1, k] * d1 + R[2, k] * d2
        out[i, 0] += rates[1] * rz - rates[2] * ry
        out[i, 1] += rates[2] * rx - rates[0] * rz
        out[i, 2] += rates[0] * ry - rates[1] * rx


@njit(cache=True, inline="always")
def _bet_wrench(v_hubs: np.ndarray, v_air: np.ndarray, rates: np.ndarray, w_rot: np.ndarray,
                w_rot_dot: np.ndarray, v_i: np.ndarray, p: np.ndarray, vi_dot: np.ndarray, fm: np.ndarray,
                loads: np.ndarray) -> None:  # fmt: skip
    """The blade-element wrench into ``fm`` (6,); ``loads`` (6,) is scratch."""
    n = int(p[P_NROT])
    # The blade parameters as scalars read once (a tuple: the rotor loop's constant arithmetic is then done once).
    b = P_BLADE0
    bp = (p[b], p[b + 1], p[b + 2], p[b + 3], p[b + 4], p[b + 5], p[b + 6], p[b + 7], p[b + 8], p[b + 9])
    rho = p[P_RHO]
    fm[:] = 0.0
    jh = p[P_JHUB]
    h_spin = 0.0  # sum of spin * w: the rotating parts' angular momentum about -z_b, per unit inertia
    alpha = 0.0  # sum of spin * w_dot, for the reaction torque
    for i in range(n):
        spin = p[P_ROT0 + 4 * i + 3]
        vi_dot[i] = rotor_loads(v_hubs[i], rates, w_rot[i], spin, v_i[i], rho, bp, loads)
        rx, ry, rz = p[P_ROT0 + 4 * i], p[P_ROT0 + 4 * i + 1], p[P_ROT0 + 4 * i + 2]
        fx, fy, fz = loads[0], loads[1], loads[2]
        fm[0] += fx
        fm[1] += fy
        fm[2] += fz
        fm[3] += loads[3] + ry * fz - rz * fy
        fm[4] += loads[4] + rz * fx - rx * fz
        fm[5] += loads[5] + rx * fy - ry * fx
        h_spin += spin * w_rot[i]
        alpha += spin * w_rot_dot[i]
    # Counter-clockwise rotors spin about -z_b: angular momentum -J h_spin z_b, moment on the body
    # -omega x h = J h_spin [q, -p, 0] (J: the hub, the blades' own act through their flapping);
    # accelerating them yaws the body +z_b (the reaction, with all the rotating inertia).
    fm[3] += jh * h_spin * rates[1]
    fm[4] -= jh * h_spin * rates[0]
    fm[5] += p[P_J] * alpha
    # Fuselage parasitic drag at the CG, -1/2 rho CdA |V| V per body axis.
    speed = math.sqrt(v_air[0] ** 2 + v_air[1] ** 2 + v_air[2] ** 2)
    q = 0.5 * rho * speed
    fm[0] -= q * p[P_CDA_X] * v_air[0]
    fm[1] -= q * p[P_CDA_Y] * v_air[1]
    fm[2] -= q * p[P_CDA_Z] * v_air[2]


@njit(cache=True)
def _sih_wrench(v_air: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, p: np.ndarray, fm: np.ndarray) -> None:
    """PX4 SIH's wrench into ``fm`` (6,)."""
    n = int(p[P_NROT])
    fm[:] = 0.0
    wmax = p[P_WMAX]
    for i in range(n):
        u = (w_rot[i] / wmax) ** 2
        t = p[P_SIH_TMAX] * u
        rx, ry = p[P_ROT0 + 4 * i], p[P_ROT0 + 4 * i + 1]
        fm[2] -= t
        fm[3] -= ry * t
        fm[4] += rx * t
        fm[5] += p[P_ROT0 + 4 * i + 3] * p[P_SIH_QMAX] * u
    for k in range(3):
        fm[k] -= p[P_SIH_KDV] * v_air[k]
        fm[3 + k] -= p[P_SIH_KDW] * rates[k]


@njit(cache=True, inline="always")
def truth_wrench(R: np.ndarray, vel: np.ndarray, rates: np.ndarray, winds: np.ndarray, w_rot: np.ndarray,
                 w_rot_dot: np.ndarray, v_i: np.ndarray, p: np.ndarray, vi_dot: np.ndarray, fm: np.ndarray,
                 v_air: np.ndarray, v_hubs: np.ndarray, loads: np.ndarray, reg: np.ndarray) -> None:  # fmt: skip
    """Forces (N) and moments about the CG (N*m), FRD ``[X, Y, Z, L, M, N]``, of the vehicle's truth,
    into ``fm`` (6,).

    ``winds`` (1 + N, 3): the air-mass velocity (NED, m/s) at the CG, then at each hub (only ``bet``
    reads the hubs). ``v_i`` (N,) induced velocities (m/s, the ``bet`` inflow states); ``vi_dot``
    receives their rates (zero for the other truths). Rotor speeds and accelerations in rad/s(^2).
    Scratch, so that an evaluation allocates nothing (the physics tick's): ``v_air`` (3,) the airspeed at
    the CG (FRD, m/s), ``v_hubs`` (MAX_ROTORS, 3) at each hub, ``loads`` (6,) one rotor's, ``reg``
    (N_COEF,) the identified model's regressors.
    """
    for k in range(3):
        v_air[k] = (R[0, k] * (vel[0] - winds[0, 0]) + R[1, k] * (vel[1] - winds[0, 1])
                    + R[2, k] * (vel[2] - winds[0, 2]))  # fmt: skip
    truth = int(p[P_TRUTH])
    if truth == TRUTH_BET:
        hub_airspeeds(R, vel, rates, winds[1:], p, v_hubs)
        _bet_wrench(v_hubs, v_air, rates, w_rot, w_rot_dot, v_i, p, vi_dot, fm, loads)
        return
    vi_dot[:] = 0.0
    if truth == TRUTH_SIH:
        _sih_wrench(v_air, rates, w_rot, p, fm)
    else:
        rotor_wrench_into(v_air, rates, w_rot, w_rot_dot, p, reg, fm)


def static_wrench(params: VehicleParams, omega: np.ndarray, rates: np.ndarray | None = None) -> np.ndarray:
    """The truth's forces and moments (FRD, N and N*m) at zero airspeed, level, rotor speeds ``omega`` (N,)
    rad/s, body ``rates`` rad/s, the inflow settled."""
    p = replace(params, control={}).as_array()
    return _steady_wrench(params, p, np.asarray(omega, dtype=float), np.zeros(3) if rates is None else rates)


def _steady_wrench(params: VehicleParams, p: np.ndarray, omega: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """The truth's wrench at zero airspeed with the inflow settled (level, no wind)."""
    n = params.n_rotors
    R = np.eye(3)
    winds = np.zeros((1 + n, 3))
    v_i = np.zeros(MAX_ROTORS)
    vi_dot = np.zeros(MAX_ROTORS)
    w = np.zeros(MAX_ROTORS)
    w[:n] = omega
    zero = np.zeros(MAX_ROTORS)
    fm = np.zeros(6)
    wk = (np.zeros(3), np.zeros((MAX_ROTORS, 3)), np.zeros(6), np.zeros(N_COEF))
    if params.truth == "bet":  # settle the inflow: its fixed point is momentum theory
        v_i[:n] = params.hover_induced_velocity_m_s
        for _ in range(400):
            truth_wrench(R, np.zeros(3), rates, winds, w, zero, v_i, p, vi_dot, fm, *wk)
            v_i[:n] += vi_dot[:n] * 0.002
    truth_wrench(R, np.zeros(3), rates, winds, w, zero, v_i, p, vi_dot, fm, *wk)
    return fm


def static_thrust(params: VehicleParams, omega: float) -> float:
    """One rotor's thrust (N) of the truth with every rotor at ``omega`` rad/s, zero airspeed, inflow settled."""
    p = replace(params, control={}).as_array()
    return float(-_steady_wrench(params, p, np.full(params.n_rotors, float(omega)), np.zeros(3))[2] / params.n_rotors)


#: :func:`with_control_figures`' figures by the vehicle they were derived from (the repr of its parameters without
#: them: every field, exactly). Deriving them settles the blade-element inflow some 50 times (about 60 ms of CPU);
#: a campaign worker loads the same vehicle file for every mission.
_FIGURES: dict[str, dict[str, Any]] = {}


def with_control_figures(params: VehicleParams) -> VehicleParams:
    """``params`` with :attr:`VehicleParams.control` derived from its truth (:func:`control_figures`; the figures
    of a vehicle seen before in this process are reused)."""
    bare = replace(params, control={})
    key = repr(bare)
    control = _FIGURES.get(key)
    if control is None:
        if len(_FIGURES) >= 64:
            _FIGURES.clear()
        control = _FIGURES[key] = control_figures(bare)
    return replace(params, control=dict(control))


def control_figures(params: VehicleParams) -> dict[str, Any]:
    """:attr:`VehicleParams.control` derived from the truth of ``params`` at zero airspeed:

    - ``kt2``, ``kt1``: one rotor's thrust ``T = kt2 w^2 + kt1 w`` (N), a least-squares fit of the
      truth's static thrust between idle and the maximum speed;
    - ``km``: rotor torque over thrust (m) at hover (PX4's ``CA_ROTORi_KM``);
    - ``damping``: the vehicle's roll, pitch and yaw rate damping at hover (N*m per rad/s);
    - ``hover_speed``: the equal rotor speed whose thrust carries the weight (rad/s).
    """
    p = replace(params, control={}).as_array()
    n = params.n_rotors
    speeds = np.linspace(max(params.rotor_speed_min_rad_s, 0.15 * params.rotor_speed_max_rad_s),
                         params.rotor_speed_max_rad_s, 9)  # fmt: skip
    thrust = np.array([-_steady_wrench(params, p, np.full(n, w), np.zeros(3))[2] / n for w in speeds])
    kt2, kt1 = np.linalg.lstsq(np.stack([speeds**2, speeds], axis=1), thrust, rcond=None)[0]
    weight = params.mass_kg * params.gravity_m_s2 / n
    hover = float((-kt1 + math.sqrt(kt1 * kt1 + 4.0 * kt2 * weight)) / (2.0 * kt2))
    for _ in range(30):  # refine on the truth itself (the fit is only a curve)
        t = -_steady_wrench(params, p, np.full(n, hover), np.zeros(3))[2] / n
        hover *= math.sqrt(weight / t)
    one = np.zeros(n)
    one[0] = 1.0
    base = _steady_wrench(params, p, np.full(n, hover), np.zeros(3))
    dw = 5.0
    d = _steady_wrench(params, p, np.full(n, hover) + dw * one, np.zeros(3)) - base
    km = abs(d[5] / d[2]) if d[2] != 0.0 else 0.0
    damping = []
    for axis in range(3):
        rate = np.zeros(3)
        rate[axis] = 0.2
        up = _steady_wrench(params, p, np.full(n, hover), rate)[3 + axis]
        down = _steady_wrench(params, p, np.full(n, hover), -rate)[3 + axis]
        damping.append(min(0.0, float((up - down) / 0.4)))
    return {"kt2": float(kt2), "kt1": float(kt1), "km": float(km), "damping": tuple(damping), "hover_speed": hover}
