"""PX4's actuator outputs to windseek's rotor speeds: motor order, thrust curve, and the checks of an output set.

**Motor order.** PX4's generic quad X (airframes 10016 ``none_iris``, 10040 ``sihsim_quadx``, HITL
1001 ``rc_quad_x.hil``; ``CA_ROTOR0..3``) numbers its motors 1 front right, 2 rear left, 3 front
left, 4 rear right; motors 1 and 2 spin counter-clockwise seen from above (``CA_ROTORi_KM > 0``).
windseek's rotors (:mod:`vehicle.rotor_model`) are 1 front right, 2 rear right, 3 rear left, 4 front
left, with rotors 1 and 3 counter-clockwise. So output ``i`` (``controls[i]``) drives rotor
:data:`PX4_TO_ROTOR` ``[i]`` and the spin directions agree (PX4's CCW pair FR + RL is windseek's
1 + 3).

**Thrust curve.** An output ``u`` in [0, 1] commands the rotor speed ``omega = omega_max * u``
(linear, like an ESC's speed command; ``omega_max`` = the vehicle file's ``rotor_speed_max_rad_s``),
and the motor follows with its first-order lag. The paper's model gives a rotor's static thrust
``T = k (C_ZT0 R^2 omega^2 + C_ZTv R v0 omega)`` (Eq. 46c at zero airspeed), so thrust over
maximum thrust is ``f u^2 + (1 - f) u`` with ``f = C_ZT0 R omega_max / (C_ZT0 R omega_max + C_ZTv
v0)``: exactly PX4's ``THR_MDL_FAC`` model, which PX4 inverts so that its outputs produce the
thrust it wants. For ``nasa_quad`` ``f`` = 0.992 and the hover thrust is 0.431 of the maximum
(``MPC_THR_HOVER``); :func:`px4_figures` computes both from the vehicle file, and the shipped
parameter file (``sitl/px4/windseek_nasa_quad.params``) carries them.

Units SI; rotor speeds rad/s; body FRD.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vehicle.params import P_B, P_R, P_RHO, P_V0, VehicleParams, coef_index
from vehicle.rotor_model import hover_rotor_speed, wrench

#: PX4 output (0-based) -> windseek rotor index (0-based): FR -> FR, RL -> RL, FL -> FL, RR -> RR.
PX4_TO_ROTOR = (0, 2, 3, 1)
#: Motors the vehicle has (PX4 outputs 1-4).
N_MOTORS = 4
#: HIL_ACTUATOR_CONTROLS carries 16 outputs.
N_OUTPUTS = 16
#: Slack on the [0, 1] motor range and on "unused output is zero" (PX4 sends float32 values).
RANGE_TOL = 1e-3
#: HIL_ACTUATOR_CONTROLS.mode bit: MAV_MODE_FLAG_SAFETY_ARMED.
MODE_ARMED = 128
#: HIL_ACTUATOR_CONTROLS.flags bit: HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP.
FLAG_LOCKSTEP = 1

_CZ_T0, _CZ_TV = coef_index("C_Z_T0"), coef_index("C_Z_Tv")


@dataclass(frozen=True)
class Px4Figures:
    """What PX4's parameters must say about a windseek vehicle (see the module docstring).

    thr_mdl_fac: PX4 ``THR_MDL_FAC``; hover_thrust: ``MPC_THR_HOVER`` (thrust / max thrust);
    max_thrust_n: one rotor's static thrust at ``omega_max`` [N]; thrust_to_weight: 4 rotors;
    km: yaw torque / thrust of one rotor at hover [m] (``CA_ROTORi_KM`` magnitude);
    arm_x_m / arm_y_m: rotor position from the CG (FRD, m) of the X geometry (``CA_ROTORi_PX/PY``);
    roll_arm_m / pitch_arm_m: the moment arms the identified model implies at hover (roll or pitch
    moment / thrust of one rotor), which differ from the geometry (see the parameter file).
    """

    thr_mdl_fac: float
    hover_thrust: float
    max_thrust_n: float
    thrust_to_weight: float
    km: float
    arm_x_m: float
    arm_y_m: float
    roll_arm_m: float
    pitch_arm_m: float


def px4_figures(vehicle: VehicleParams) -> Px4Figures:
    """PX4 parameter values for ``vehicle`` from its rotor model (zero airspeed, SI)."""
    p = vehicle.as_array()
    w_max = float(vehicle.rotor_speed_max_rad_s)
    k = p[P_RHO] * math.pi * p[P_R] ** 2
    a = k * p[_CZ_T0] * p[P_R] ** 2  # thrust per omega^2
    b = k * p[_CZ_TV] * p[P_R] * p[P_V0]  # thrust per omega
    t_max = a * w_max**2 + b * w_max
    w_hover = hover_rotor_speed(vehicle)
    t_hover = a * w_hover**2 + b * w_hover
    one = np.zeros(4)
    one[0] = w_hover  # rotor 1 (front right, CCW) alone
    f = wrench(vehicle, np.zeros(3), np.zeros(3), one)
    thrust = -f[2]
    arm = float(p[P_B]) / math.sqrt(2.0)
    weight = vehicle.mass_kg * vehicle.gravity_m_s2
    return Px4Figures(thr_mdl_fac=float(a * w_max**2 / t_max), hover_thrust=float(t_hover / t_max),
                      max_thrust_n=float(t_max), thrust_to_weight=float(4 * t_max / weight),
                      km=float(abs(f[5]) / thrust), arm_x_m=arm, arm_y_m=arm, roll_arm_m=float(abs(f[3]) / thrust),
                      pitch_arm_m=float(abs(f[4]) / thrust))  # fmt: skip


@dataclass(frozen=True)
class Verdict:
    """The check of one HIL_ACTUATOR_CONTROLS: ``speeds`` (rad/s, windseek's rotor order) when it
    can drive the world, else ``problem`` (a counter name) and ``why`` (one line)."""

    speeds: np.ndarray | None
    armed: bool
    problem: str = ""
    why: str = ""


class MotorMap:
    """Maps and checks PX4 output sets for a vehicle (see the module docstring)."""

    def __init__(self, vehicle: VehicleParams) -> None:
        self.omega_max = float(vehicle.rotor_speed_max_rad_s)
        self._order = np.array(PX4_TO_ROTOR)
        self._order_list = list(PX4_TO_ROTOR)

    def speeds(self, outputs: np.ndarray) -> np.ndarray:
        """Rotor speed commands (rad/s, windseek order) of PX4 motor outputs 1-4 in [0, 1]."""
        w = np.empty(N_MOTORS)
        w[self._order] = self.omega_max * np.clip(np.asarray(outputs[:N_MOTORS], dtype=float), 0.0, 1.0)
        return w

    def outputs(self, speeds: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`speeds`: PX4 motor outputs 1-4 of rotor speeds (rad/s, windseek order)."""
        return np.asarray(speeds, dtype=float)[self._order] / self.omega_max

    def check(self, controls: object, mode: int) -> Verdict:
        """Check a HIL_ACTUATOR_CONTROLS ``controls`` array (16 floats) and ``mode`` word.

        Refused: a wrong length, NaN or infinite values, motor outputs outside [0, 1], and any of
        outputs 5-16 driven while armed (an airframe with more motors or servos than this quad).
        Disarmed, PX4 sends zeros: the rotors stop. Plain Python on purpose: this runs once per
        lockstep step, and numpy's call overhead on 16 numbers is several times the work.
        """
        armed = bool(int(mode) & MODE_ARMED)
        try:
            c = list(map(float, controls))  # type: ignore[call-overload]
        except (TypeError, ValueError):
            return Verdict(None, armed, "bad_length", "controls is not a sequence of numbers")
        if len(c) != N_OUTPUTS:
            return Verdict(None, armed, "bad_length", f"expected {N_OUTPUTS} outputs, got {len(c)}")
        if not all(map(math.isfinite, c)):
            bad = [i + 1 for i, v in enumerate(c) if not math.isfinite(v)]
            return Verdict(None, armed, "non_finite", f"NaN or infinite value on output(s) {bad}")
        m = c[:N_MOTORS]
        if min(m) < -RANGE_TOL or max(m) > 1.0 + RANGE_TOL:
            return Verdict(None, armed, "out_of_range", f"motor outputs {[round(v, 3) for v in m]} outside [0, 1]")
        if armed and max(map(abs, c[N_MOTORS:])) > RANGE_TOL:
            outs = ", ".join(str(i + 1) for i, v in enumerate(c) if i >= N_MOTORS and abs(v) > RANGE_TOL)
            return Verdict(None, armed, "wrong_airframe",
                           f"PX4 drives output(s) {outs}; windseek's vehicle is a quad X on outputs 1-4 (load "
                           "sitl/px4/windseek_nasa_quad.params: CA_ROTOR_COUNT 4, outputs 1-4 = motors)")  # fmt: skip
        if not armed:
            return Verdict(np.zeros(N_MOTORS), armed)
        w = self.omega_max
        o = self._order_list
        speeds = [0.0] * N_MOTORS
        for i in range(N_MOTORS):
            speeds[o[i]] = w * min(max(m[i], 0.0), 1.0)
        return Verdict(np.array(speeds), armed)
