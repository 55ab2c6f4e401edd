"""Built-in flight controller: cascaded position -> velocity -> attitude -> rate control and
allocation to rotor speeds (numba, runs every tick).

What it knows of its vehicle is what a flight controller is tuned with, derived from the vehicle's
truth at load (:func:`vehicle.truth.with_control_figures`): each rotor's static thrust curve
``T = kt2 w^2 + kt1 w``, the rotors' positions and spins, their torque-to-thrust ratio, the rate
damping at hover, the mass and the inertia. It never reads the identified model (the estimator's).

Frames and units: NED world, FRD body, SI. The controller reads the true state (the SITL
stands in for the autopilot's own state estimator; documented assumption) and a setpoint
vector written by the mode logic (``sitl.autopilot.flight_modes``):

  SP_POS (3)  position setpoint, NED, m
  SP_VEL (3)  velocity feed-forward / setpoint, NED, m/s
  SP_ACC (3)  acceleration feed-forward, NED, m/s^2
  SP_YAW      yaw setpoint, rad;  SP_YAWRATE  yaw-rate feed-forward, rad/s
  SP_FLAGS    bit 0: position valid, bit 1: velocity valid, bit 2: acceleration valid,
              bit 3: yaw valid (else hold current yaw rate 0), bit 4: motors off (disarmed),
              bit 5: attitude setpoint (SP_ATT quaternion + SP_THRUST, bypasses pos/vel)
  SP_ATT (4), SP_THRUST (normalized collective 0..1)

Gains live in :class:`ControllerGains`; names follow PX4's parameters where one exists so a
ground station can tune them through the parameter protocol.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import NamedTuple

import numpy as np
from numba import njit

from vehicle.frames import dcm_to_quat_into, quat_mul_into
from vehicle.params import (
    MAX_ROTORS,
    P_ALLOC0,
    P_DAMP_P,
    P_G,
    P_IXX,
    P_IYY,
    P_IZZ,
    P_KT1,
    P_KT2,
    P_MASS,
    P_NROT,
    P_WMAX,
    P_WMIN,
)

SP_POS, SP_VEL, SP_ACC, SP_YAW, SP_YAWRATE, SP_FLAGS, SP_ATT, SP_THRUST = 0, 3, 6, 9, 10, 11, 12, 16
N_SP = 17
F_POS, F_VEL, F_ACC, F_YAW, F_OFF, F_ATT = 1, 2, 4, 8, 16, 32
F_IDLE = 64  # rotors at armed idle (on the ground, not taking off)

# Controller memory: velocity integrator (3), rate integrator (3), previous rates (3).
N_CTRL_STATE = 9


@dataclass
class ControllerGains:
    """Flight-controller gains and limits (SI, rad). PX4-like names in comments."""

    pos_p_xy: float = 0.95  # MPC_XY_P, 1/s
    pos_p_z: float = 1.0  # MPC_Z_P, 1/s
    vel_p_xy: float = 1.8  # MPC_XY_VEL_P_ACC, 1/s
    vel_i_xy: float = 0.6  # MPC_XY_VEL_I_ACC, 1/s^2
    vel_d_xy: float = 0.1  # MPC_XY_VEL_D_ACC
    vel_p_z: float = 4.0  # MPC_Z_VEL_P_ACC
    vel_i_z: float = 2.0  # MPC_Z_VEL_I_ACC
    vel_max_xy: float = 12.0  # MPC_XY_VEL_MAX, m/s
    vel_max_up: float = 3.0  # MPC_Z_VEL_MAX_UP, m/s
    vel_max_down: float = 1.5  # MPC_Z_VEL_MAX_DN, m/s
    acc_max_xy: float = 5.0  # MPC_ACC_HOR_MAX, m/s^2
    tilt_max: float = math.radians(35.0)  # MPC_TILTMAX_AIR, rad
    att_p_rp: float = 4.0  # MC_ROLL_P / MC_PITCH_P, 1/s
    att_p_yaw: float = 2.0  # MC_YAW_P, 1/s
    rate_p_rp: float = 20.0  # MC_ROLLRATE_P (as angular-acceleration gain), 1/s
    rate_i_rp: float = 20.0  # MC_ROLLRATE_I, 1/s^2
    rate_d_rp: float = 0.15  # MC_ROLLRATE_D
    rate_p_yaw: float = 6.0  # MC_YAWRATE_P
    rate_i_yaw: float = 3.0  # MC_YAWRATE_I
    rate_max_rp: float = math.radians(150.0)  # MC_ROLLRATE_MAX, rad/s
    rate_max_yaw: float = math.radians(45.0)  # MC_YAWRATE_MAX, rad/s
    vel_int_lim: float = 4.0  # m/s^2
    rate_int_lim: float = 150.0  # rad/s^2 (trims aerodynamic moments in wind)

    def as_array(self) -> np.ndarray:
        return np.array([getattr(self, f.name) for f in fields(self)], dtype=np.float64)

    def validate(self) -> None:
        for name, value in asdict(self).items():
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"controller.{name} = {value!r}: must be finite and >= 0")
        if not (0.0 < self.tilt_max < math.radians(89.0)):
            raise ValueError(f"controller.tilt_max = {self.tilt_max}: allowed range is (0, 1.553) rad")


GAIN_NAMES = tuple(f.name for f in fields(ControllerGains))
(
    G_POS_P_XY, G_POS_P_Z, G_VEL_P_XY, G_VEL_I_XY, G_VEL_D_XY, G_VEL_P_Z, G_VEL_I_Z,
    G_VEL_MAX_XY, G_VEL_MAX_UP, G_VEL_MAX_DN, G_ACC_MAX_XY, G_TILT_MAX,
    G_ATT_P_RP, G_ATT_P_YAW, G_RATE_P_RP, G_RATE_I_RP, G_RATE_D_RP, G_RATE_P_YAW,
    G_RATE_I_YAW, G_RATE_MAX_RP, G_RATE_MAX_YAW, G_VEL_INT_LIM, G_RATE_INT_LIM,
) = range(len(GAIN_NAMES))  # fmt: skip


@njit(cache=True)
def _clip(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


class ControlWork(NamedTuple):
    """Scratch of one controller update, allocated once per fused loop (:func:`control_work`), so a
    tick allocates nothing."""

    Rd: np.ndarray  # (3, 3) the desired attitude, body -> NED
    quats: np.ndarray  # (3, 4) the attitude setpoint, the inverse attitude, the attitude error
    alloc: np.ndarray  # (4, MAX_ROTORS) allocation: collective, roll/pitch, yaw, total thrust per rotor, N


@njit(cache=True)
def control_work() -> ControlWork:
    """A fresh :class:`ControlWork` (once per fused loop, not per tick)."""
    return ControlWork(np.zeros((3, 3)), np.zeros((3, 4)), np.zeros((4, MAX_ROTORS)))


@njit(cache=True)
def control(
    x: np.ndarray,
    sp: np.ndarray,
    g: np.ndarray,
    cs: np.ndarray,
    p: np.ndarray,
    dt: float,
    out_accel_sp: np.ndarray,
    w_cmd: np.ndarray,
    wk: ControlWork,
) -> None:
    """One controller update: rotor speed commands (MAX_ROTORS,) rad/s into ``w_cmd``.

    ``cs`` is the controller memory (integrators), updated in place. ``out_accel_sp``
    receives the commanded NED acceleration (m/s^2) for telemetry. ``wk``: scratch.
    """
    flags = int(sp[SP_FLAGS])
    if flags & F_OFF:
        cs[:] = 0.0
        out_accel_sp[:] = 0.0
        w_cmd[:] = 0.0
        return
    q_sp, qi, qe = wk.quats[0], wk.quats[1], wk.quats[2]
    if flags & F_ATT:
        q_sp[:] = sp[SP_ATT:SP_ATT + 4]
        thrust = _clip(sp[SP_THRUST], 0.0, 1.0) * _max_thrust(p)
        out_accel_sp[:] = 0.0
    else:
        thrust = _attitude_setpoint(x, sp, g, cs, p, dt, out_accel_sp, wk.Rd, q_sp)
    yawrate_ff = sp[SP_YAWRATE]
    # --- attitude -> body rates: q_err = q^-1 * q_sp, rate = 2 K sign(w) v
    qi[0], qi[1], qi[2], qi[3] = x[6], -x[7], -x[8], -x[9]
    quat_mul_into(qi, q_sp, qe)
    s = 1.0 if qe[0] >= 0.0 else -1.0
    rs0 = _clip(2.0 * s * qe[1] * g[G_ATT_P_RP], -g[G_RATE_MAX_RP], g[G_RATE_MAX_RP])
    rs1 = _clip(2.0 * s * qe[2] * g[G_ATT_P_RP], -g[G_RATE_MAX_RP], g[G_RATE_MAX_RP])
    rs2 = _clip(2.0 * s * qe[3] * g[G_ATT_P_YAW] + yawrate_ff, -g[G_RATE_MAX_YAW], g[G_RATE_MAX_YAW])
    # --- rates -> moments: I * (PI + D on measurement) + gyroscopic + damping feed-forward
    ilim = g[G_RATE_INT_LIM]
    aa0 = _rate_pid(0, rs0, x[10], g, cs, dt, ilim)
    aa1 = _rate_pid(1, rs1, x[11], g, cs, dt, ilim)
    aa2 = _rate_pid(2, rs2, x[12], g, cs, dt, ilim)
    ixx, iyy, izz = p[P_IXX], p[P_IYY], p[P_IZZ]
    r0, r1, r2 = x[10], x[11], x[12]
    iw0, iw1, iw2 = ixx * r0, iyy * r1, izz * r2
    # (the sums in numpy's order: I * alpha, plus rates x I w, then the damping feed-forward)
    m0 = ixx * aa0 + (r1 * iw2 - r2 * iw1)
    m1 = iyy * aa1 + (r2 * iw0 - r0 * iw2)
    m2 = izz * aa2 + (r0 * iw1 - r1 * iw0)
    # The rotors damp body rates (blade flapping, inflow): feed the damping at the rate setpoint
    # forward so the PI loop only corrects the residual.
    m0 -= p[P_DAMP_P] * rs0
    m1 -= p[P_DAMP_P + 1] * rs1
    m2 -= p[P_DAMP_P + 2] * rs2
    allocate(thrust, m0, m1, m2, p, w_cmd, wk.alloc)


@njit(cache=True, inline="always")
def _rate_pid(i: int, rate_sp: float, rate: float, g: np.ndarray, cs: np.ndarray, dt: float, ilim: float) -> float:
    """The rate loop of body axis ``i`` (rad/s in): its angular acceleration command, rad/s^2; the
    integrator and the previous rate in ``cs`` updated."""
    e = rate_sp - rate
    kp = g[G_RATE_P_YAW] if i == 2 else g[G_RATE_P_RP]
    ki = g[G_RATE_I_YAW] if i == 2 else g[G_RATE_I_RP]
    kd = 0.0 if i == 2 else g[G_RATE_D_RP]
    cs[3 + i] = _clip(cs[3 + i] + ki * e * dt, -ilim, ilim)
    d = (rate - cs[6 + i]) / dt
    cs[6 + i] = rate
    return kp * e + cs[3 + i] - kd * d


@njit(cache=True)
def _attitude_setpoint(
    x: np.ndarray, sp: np.ndarray, g: np.ndarray, cs: np.ndarray, p: np.ndarray, dt: float,
    out_accel_sp: np.ndarray, Rd: np.ndarray, q_sp: np.ndarray,
) -> float:  # fmt: skip
    """Position -> velocity -> acceleration -> thrust vector: the attitude setpoint into ``q_sp``
    (body -> NED) and the collective thrust (N, returned). ``Rd`` (3, 3): scratch."""
    flags = int(sp[SP_FLAGS])
    # --- position -> velocity
    v0 = v1 = v2 = 0.0
    if flags & F_VEL:
        v0, v1, v2 = sp[SP_VEL], sp[SP_VEL + 1], sp[SP_VEL + 2]
    if flags & F_POS:
        v0 += g[G_POS_P_XY] * (sp[SP_POS] - x[0])
        v1 += g[G_POS_P_XY] * (sp[SP_POS + 1] - x[1])
        v2 += g[G_POS_P_Z] * (sp[SP_POS + 2] - x[2])
    vh = math.hypot(v0, v1)
    if vh > g[G_VEL_MAX_XY]:
        v0 *= g[G_VEL_MAX_XY] / vh
        v1 *= g[G_VEL_MAX_XY] / vh
    v2 = _clip(v2, -g[G_VEL_MAX_UP], g[G_VEL_MAX_DN])
    # --- velocity -> acceleration (PID, integrator with anti-windup clamp)
    a0 = a1 = a2 = 0.0
    if flags & F_ACC:
        a0, a1, a2 = sp[SP_ACC], sp[SP_ACC + 1], sp[SP_ACC + 2]
    lim = g[G_VEL_INT_LIM]
    a0 += _vel_pi(0, v0, x[3], g, cs, dt, lim)
    a1 += _vel_pi(1, v1, x[4], g, cs, dt, lim)
    a2 += _vel_pi(2, v2, x[5], g, cs, dt, lim)
    ah = math.hypot(a0, a1)
    if ah > g[G_ACC_MAX_XY]:
        a0 *= g[G_ACC_MAX_XY] / ah
        a1 *= g[G_ACC_MAX_XY] / ah
    out_accel_sp[0], out_accel_sp[1], out_accel_sp[2] = a0, a1, a2
    # --- acceleration -> thrust vector (specific force f = a - g e3), tilt limited
    grav = p[P_G]
    f0, f1, f2 = a0, a1, min(a2 - grav, -0.2 * grav)
    fh = math.hypot(f0, f1)
    max_h = -f2 * math.tan(g[G_TILT_MAX])
    if fh > max_h:
        f0 *= max_h / fh
        f1 *= max_h / fh
    fn = math.sqrt(f0**2 + f1**2 + f2**2)
    thrust = p[P_MASS] * fn
    z0, z1, z2 = -f0 / fn, -f1 / fn, -f2 / fn
    if flags & F_YAW:
        yaw_sp = sp[SP_YAW]
    else:
        yaw_sp = math.atan2(2 * (x[6] * x[9] + x[7] * x[8]), 1 - 2 * (x[8] ** 2 + x[9] ** 2))
    c0, c1, c2 = math.cos(yaw_sp), math.sin(yaw_sp), 0.0
    # body y = z x c (normalized), body x = y x z: the cross products as numpy's np.cross forms them
    y0, y1, y2 = z1 * c2 - z2 * c1, z2 * c0 - z0 * c2, z0 * c1 - z1 * c0
    yn = math.sqrt(y0**2 + y1**2 + y2**2)
    y0, y1, y2 = y0 / yn, y1 / yn, y2 / yn
    Rd[0, 0], Rd[1, 0], Rd[2, 0] = y1 * z2 - y2 * z1, y2 * z0 - y0 * z2, y0 * z1 - y1 * z0
    Rd[0, 1], Rd[1, 1], Rd[2, 1] = y0, y1, y2
    Rd[0, 2], Rd[1, 2], Rd[2, 2] = z0, z1, z2
    dcm_to_quat_into(Rd, q_sp)
    return thrust


@njit(cache=True, inline="always")
def _vel_pi(i: int, vel_sp: float, vel: float, g: np.ndarray, cs: np.ndarray, dt: float, lim: float) -> float:
    """The velocity loop of NED axis ``i`` (m/s in): its acceleration command, m/s^2; the integrator updated."""
    e = vel_sp - vel
    kp = g[G_VEL_P_Z] if i == 2 else g[G_VEL_P_XY]
    ki = g[G_VEL_I_Z] if i == 2 else g[G_VEL_I_XY]
    cs[i] = _clip(cs[i] + ki * e * dt, -lim, lim)
    return kp * e + cs[i]


@njit(cache=True)
def allocate(thrust: float, m0: float, m1: float, m2: float, p: np.ndarray, out: np.ndarray,
             work: np.ndarray) -> None:  # fmt: skip
    """Rotor speeds (rad/s) into ``out`` for a collective thrust (N) and moments ``m0, m1, m2`` (N*m,
    FRD): per-rotor thrusts from the allocation matrix (``P_ALLOC0``), with saturation handled as PX4
    does: yaw is given up first, then roll/pitch is scaled, then the collective shifts (attitude over
    thrust). Thrust -> speed by the rotor's static thrust curve. ``work`` (4, MAX_ROTORS): scratch."""
    n = int(p[P_NROT])
    kt2, kt1 = p[P_KT2], p[P_KT1]
    t_min = kt2 * p[P_WMIN] ** 2 + kt1 * p[P_WMIN]
    t_max = kt2 * p[P_WMAX] ** 2 + kt1 * p[P_WMAX]
    base, d, y, t = work[0, :n], work[1, :n], work[2, :n], work[3, :n]
    for i in range(n):
        a = P_ALLOC0 + 4 * i
        base[i] = p[a] * thrust
        d[i] = p[a + 1] * m0 + p[a + 2] * m1
        y[i] = p[a + 3] * m2
    # Roll/pitch alone: scale down if the span cannot fit between the limits at all.
    span = d.max() - d.min()
    if span > t_max - t_min:
        c = (t_max - t_min) / span
        for i in range(n):
            d[i] *= c
    # Yaw: largest fraction that still fits with roll/pitch at the current collective.
    scale_y = 1.0
    for i in range(n):
        tot = base[i] + d[i] + y[i]
        if tot > t_max and y[i] > 0.0:
            scale_y = min(scale_y, max(0.0, (t_max - base[i] - d[i]) / y[i]))
        elif tot < t_min and y[i] < 0.0:
            scale_y = min(scale_y, max(0.0, (t_min - base[i] - d[i]) / y[i]))
    for i in range(n):
        t[i] = base[i] + d[i] + scale_y * y[i]
    # Shift the collective to bring everything inside the limits.
    top = t.max()
    bot = t.min()
    if top > t_max:
        shift = top - t_max
        for i in range(n):
            t[i] -= shift
    elif bot < t_min:
        shift = t_min - bot
        for i in range(n):
            t[i] += shift
    out[:] = 0.0
    for i in range(n):
        ti = min(max(t[i], t_min), t_max)
        out[i] = (-kt1 + math.sqrt(kt1 * kt1 + 4.0 * kt2 * ti)) / (2.0 * kt2)


@njit(cache=True)
def _max_thrust(p: np.ndarray) -> float:
    """Collective thrust (N) with every rotor at its maximum speed, zero airspeed."""
    w = p[P_WMAX]
    return p[P_NROT] * (p[P_KT2] * w * w + p[P_KT1] * w)
