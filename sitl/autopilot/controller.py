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

import numpy as np
from numba import njit

from vehicle.frames import dcm_to_quat, quat_mul
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


@njit(cache=True)
def control(
    x: np.ndarray,
    sp: np.ndarray,
    g: np.ndarray,
    cs: np.ndarray,
    p: np.ndarray,
    dt: float,
    out_accel_sp: np.ndarray,
) -> np.ndarray:
    """One controller update. Returns rotor speed commands (MAX_ROTORS,), rad/s.

    ``cs`` is the controller memory (integrators), updated in place. ``out_accel_sp``
    receives the commanded NED acceleration (m/s^2) for telemetry.
    """
    flags = int(sp[SP_FLAGS])
    w_cmd = np.zeros(MAX_ROTORS)
    if flags & F_OFF:
        cs[:] = 0.0
        out_accel_sp[:] = 0.0
        return w_cmd
    m = p[P_MASS]
    grav = p[P_G]
    q = x[6:10]
    rates = x[10:13]
    if flags & F_ATT:
        q_sp = sp[SP_ATT:SP_ATT + 4].copy()
        thrust = _clip(sp[SP_THRUST], 0.0, 1.0) * _max_thrust(p)
        yawrate_ff = sp[SP_YAWRATE]
        out_accel_sp[:] = 0.0
    else:
        # --- position -> velocity
        vel_sp = np.zeros(3)
        if flags & F_VEL:
            vel_sp[:] = sp[SP_VEL:SP_VEL + 3]
        if flags & F_POS:
            vel_sp[0] += g[G_POS_P_XY] * (sp[SP_POS] - x[0])
            vel_sp[1] += g[G_POS_P_XY] * (sp[SP_POS + 1] - x[1])
            vel_sp[2] += g[G_POS_P_Z] * (sp[SP_POS + 2] - x[2])
        vh = math.hypot(vel_sp[0], vel_sp[1])
        if vh > g[G_VEL_MAX_XY]:
            vel_sp[0] *= g[G_VEL_MAX_XY] / vh
            vel_sp[1] *= g[G_VEL_MAX_XY] / vh
        vel_sp[2] = _clip(vel_sp[2], -g[G_VEL_MAX_UP], g[G_VEL_MAX_DN])
        # --- velocity -> acceleration (PID, integrator with anti-windup clamp)
        acc = np.zeros(3)
        if flags & F_ACC:
            acc[:] = sp[SP_ACC:SP_ACC + 3]
        lim = g[G_VEL_INT_LIM]
        for i in range(3):
            e = vel_sp[i] - x[3 + i]
            kp = g[G_VEL_P_Z] if i == 2 else g[G_VEL_P_XY]
            ki = g[G_VEL_I_Z] if i == 2 else g[G_VEL_I_XY]
            cs[i] = _clip(cs[i] + ki * e * dt, -lim, lim)
            acc[i] += kp * e + cs[i]
        ah = math.hypot(acc[0], acc[1])
        if ah > g[G_ACC_MAX_XY]:
            acc[0] *= g[G_ACC_MAX_XY] / ah
            acc[1] *= g[G_ACC_MAX_XY] / ah
        out_accel_sp[:] = acc
        # --- acceleration -> thrust vector (specific force f = a - g e3), tilt limited
        f = np.array([acc[0], acc[1], min(acc[2] - grav, -0.2 * grav)])
        fh = math.hypot(f[0], f[1])
        max_h = -f[2] * math.tan(g[G_TILT_MAX])
        if fh > max_h:
            f[0] *= max_h / fh
            f[1] *= max_h / fh
        fn = math.sqrt(f[0] ** 2 + f[1] ** 2 + f[2] ** 2)
        thrust = m * fn
        zb = -f / fn
        if flags & F_YAW:
            yaw_sp = sp[SP_YAW]
        else:
            yaw_sp = math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))
        xc = np.array([math.cos(yaw_sp), math.sin(yaw_sp), 0.0])
        yb = np.cross(zb, xc)
        yb /= math.sqrt(yb[0] ** 2 + yb[1] ** 2 + yb[2] ** 2)
        xb = np.cross(yb, zb)
        Rd = np.empty((3, 3))
        Rd[:, 0] = xb
        Rd[:, 1] = yb
        Rd[:, 2] = zb
        q_sp = dcm_to_quat(Rd)
        yawrate_ff = sp[SP_YAWRATE]
    # --- attitude -> body rates: q_err = q^-1 * q_sp, rate = 2 K sign(w) v
    qi = np.array([q[0], -q[1], -q[2], -q[3]])
    qe = quat_mul(qi, q_sp)
    s = 1.0 if qe[0] >= 0.0 else -1.0
    rate_sp = np.empty(3)
    rate_sp[0] = _clip(2.0 * s * qe[1] * g[G_ATT_P_RP], -g[G_RATE_MAX_RP], g[G_RATE_MAX_RP])
    rate_sp[1] = _clip(2.0 * s * qe[2] * g[G_ATT_P_RP], -g[G_RATE_MAX_RP], g[G_RATE_MAX_RP])
    rate_sp[2] = _clip(
        2.0 * s * qe[3] * g[G_ATT_P_YAW] + yawrate_ff, -g[G_RATE_MAX_YAW], g[G_RATE_MAX_YAW]
    )
    # --- rates -> moments: I * (PI + D on measurement) + gyroscopic + damping feed-forward
    inertia = np.array([p[P_IXX], p[P_IYY], p[P_IZZ]])
    ang_acc = np.empty(3)
    ilim = g[G_RATE_INT_LIM]
    for i in range(3):
        e = rate_sp[i] - rates[i]
        kp = g[G_RATE_P_YAW] if i == 2 else g[G_RATE_P_RP]
        ki = g[G_RATE_I_YAW] if i == 2 else g[G_RATE_I_RP]
        kd = 0.0 if i == 2 else g[G_RATE_D_RP]
        cs[3 + i] = _clip(cs[3 + i] + ki * e * dt, -ilim, ilim)
        d = (rates[i] - cs[6 + i]) / dt
        cs[6 + i] = rates[i]
        ang_acc[i] = kp * e + cs[3 + i] - kd * d
    mom = inertia * ang_acc
    iw = inertia * rates
    mom += np.cross(rates, iw)
    # The rotors damp body rates (blade flapping, inflow): feed the damping at the rate setpoint
    # forward so the PI loop only corrects the residual.
    for i in range(3):
        mom[i] -= p[P_DAMP_P + i] * rate_sp[i]
    return allocate(thrust, mom, p, w_cmd)


@njit(cache=True)
def allocate(thrust: float, mom: np.ndarray, p: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Rotor speeds (rad/s) for a collective thrust (N) and moments (N*m, FRD): per-rotor thrusts from
    the allocation matrix (``P_ALLOC0``), with saturation handled as PX4 does: yaw is given up first,
    then roll/pitch is scaled, then the collective shifts (attitude over thrust). Thrust -> speed by
    the rotor's static thrust curve."""
    n = int(p[P_NROT])
    kt2, kt1 = p[P_KT2], p[P_KT1]
    t_min = kt2 * p[P_WMIN] ** 2 + kt1 * p[P_WMIN]
    t_max = kt2 * p[P_WMAX] ** 2 + kt1 * p[P_WMAX]
    base = np.empty(n)
    d = np.empty(n)
    y = np.empty(n)
    for i in range(n):
        a = P_ALLOC0 + 4 * i
        base[i] = p[a] * thrust
        d[i] = p[a + 1] * mom[0] + p[a + 2] * mom[1]
        y[i] = p[a + 3] * mom[2]
    # Roll/pitch alone: scale down if the span cannot fit between the limits at all.
    span = d.max() - d.min()
    if span > t_max - t_min:
        d *= (t_max - t_min) / span
    # Yaw: largest fraction that still fits with roll/pitch at the current collective.
    scale_y = 1.0
    for i in range(n):
        tot = base[i] + d[i] + y[i]
        if tot > t_max and y[i] > 0.0:
            scale_y = min(scale_y, max(0.0, (t_max - base[i] - d[i]) / y[i]))
        elif tot < t_min and y[i] < 0.0:
            scale_y = min(scale_y, max(0.0, (t_min - base[i] - d[i]) / y[i]))
    t = base + d + scale_y * y
    # Shift the collective to bring everything inside the limits.
    top = t.max()
    bot = t.min()
    if top > t_max:
        t -= top - t_max
    elif bot < t_min:
        t += t_min - bot
    out[:] = 0.0
    for i in range(n):
        ti = min(max(t[i], t_min), t_max)
        out[i] = (-kt1 + math.sqrt(kt1 * kt1 + 4.0 * kt2 * ti)) / (2.0 * kt2)
    return out


@njit(cache=True)
def _max_thrust(p: np.ndarray) -> float:
    """Collective thrust (N) with every rotor at its maximum speed, zero airspeed."""
    w = p[P_WMAX]
    return p[P_NROT] * (p[P_KT2] * w * w + p[P_KT1] * w)
