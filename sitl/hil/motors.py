"""PX4's actuator outputs to windseek's rotor speeds: motor order, thrust curve, and the checks of an output set.

**Motor order.** Each rotor of a vehicle file carries the PX4 output that drives it
(``[frame] px4_outputs``). PX4's generic quad X (airframes 10016 ``none_iris``, 10040
``sihsim_quadx``, HITL 1001 ``rc_quad_x.hil``; ``CA_ROTOR0..3``) numbers its motors 1 front right,
2 rear left, 3 front left, 4 rear right; motors 1 and 2 spin counter-clockwise seen from above
(``CA_ROTORi_KM > 0``). windseek's quad X rotors (Eq. 42) are 1 front right, 2 rear right, 3 rear
left, 4 front left, with rotors 1 and 3 counter-clockwise: output ``i`` (``controls[i]``) drives rotor
:data:`PX4_TO_ROTOR` ``[i]`` and the spin directions agree. The hexarotor X's rotors are in PX4's own
order.

**Thrust curve.** An output ``u`` in [0, 1] commands the rotor speed ``omega = omega_max * u``
(linear, like an ESC's speed command; ``omega_max`` = the vehicle file's ``rotor_speed_max_rad_s``),
and the motor follows with its first-order lag. The vehicle's truth gives a rotor's static thrust
``T = kt2 omega^2 + kt1 omega`` (:func:`vehicle.truth.with_control_figures`), so thrust over maximum
thrust is ``f u^2 + (1 - f) u`` with ``f = kt2 omega_max / (kt2 omega_max + kt1)``: exactly PX4's
``THR_MDL_FAC`` model, which PX4 inverts so that its outputs produce the thrust it wants.
:func:`px4_figures` computes it and the hover thrust (``MPC_THR_HOVER``) from the vehicle file, and
the shipped parameter files (``sitl/px4/windseek_*.params``) carry them.

Units SI; rotor speeds rad/s; body FRD.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from vehicle.params import VehicleParams

#: PX4 output (0-based) -> windseek rotor index (0-based) of the quad X: FR -> FR, RL -> RL, FL -> FL, RR -> RR.
PX4_TO_ROTOR = (0, 2, 3, 1)
#: HIL_ACTUATOR_CONTROLS carries 16 outputs.
N_OUTPUTS = 16
#: Slack on the [0, 1] motor range and on "unused output is zero" (PX4 sends float32 values).
RANGE_TOL = 1e-3
#: HIL_ACTUATOR_CONTROLS.mode bit: MAV_MODE_FLAG_SAFETY_ARMED.
MODE_ARMED = 128
#: HIL_ACTUATOR_CONTROLS.flags bit: HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP.
FLAG_LOCKSTEP = 1


@dataclass(frozen=True)
class Px4Figures:
    """What PX4's parameters must say about a windseek vehicle (see the module docstring).

    thr_mdl_fac: PX4 ``THR_MDL_FAC``; hover_thrust: ``MPC_THR_HOVER`` (thrust / max thrust);
    max_thrust_n: one rotor's static thrust at ``omega_max`` [N]; thrust_to_weight: all rotors;
    km: yaw torque / thrust of one rotor at hover [m] (``CA_ROTORi_KM`` magnitude);
    rotors: per PX4 motor (PX4's order) its position from the CG (FRD x, y, m) and its spin (+1 CCW).
    """

    thr_mdl_fac: float
    hover_thrust: float
    max_thrust_n: float
    thrust_to_weight: float
    km: float
    rotors: tuple[tuple[float, float, int], ...]


def px4_figures(vehicle: VehicleParams) -> Px4Figures:
    """PX4 parameter values for ``vehicle`` from its truth's control figures (zero airspeed, SI)."""
    c = vehicle.control
    w_max = float(vehicle.rotor_speed_max_rad_s)
    a, b = c["kt2"], c["kt1"]  # thrust per omega^2, per omega
    t_max = a * w_max**2 + b * w_max
    w_hover = c["hover_speed"]
    t_hover = a * w_hover**2 + b * w_hover
    weight = vehicle.mass_kg * vehicle.gravity_m_s2
    order = rotors_of_outputs(vehicle)
    rotors = tuple((float(vehicle.rotor_positions_m[r][0]), float(vehicle.rotor_positions_m[r][1]),
                    int(vehicle.rotor_spins[r])) for r in order)  # fmt: skip
    return Px4Figures(thr_mdl_fac=float(a * w_max**2 / t_max), hover_thrust=float(t_hover / t_max),
                      max_thrust_n=float(t_max), thrust_to_weight=float(vehicle.n_rotors * t_max / weight),
                      km=float(c["km"]), rotors=rotors)  # fmt: skip


def rotors_of_outputs(vehicle: VehicleParams) -> tuple[int, ...]:
    """windseek rotor index (0-based) driven by each PX4 output 0..N-1 (the inverse of ``px4_outputs``)."""
    n = vehicle.n_rotors
    outs = vehicle.px4_outputs or tuple(range(n))
    if sorted(outs) != list(range(n)):
        raise ValueError(f"vehicle {vehicle.name}: frame.px4_outputs must number the rotors' outputs 1-{n} once each")
    order = [0] * n
    for rotor, out in enumerate(outs):
        order[out] = rotor
    return tuple(order)


class Verdict(NamedTuple):
    """The check of one HIL_ACTUATOR_CONTROLS: ``speeds`` (rad/s, windseek's rotor order) when it
    can drive the world, else ``problem`` (a counter name) and ``why`` (one line). A tuple: one is
    made per lockstep step, and a frozen dataclass costs several times as much to build."""

    speeds: np.ndarray | None
    armed: bool
    problem: str = ""
    why: str = ""


class MotorMap:
    """Maps and checks PX4 output sets for a vehicle (see the module docstring)."""

    def __init__(self, vehicle: VehicleParams) -> None:
        self.omega_max = float(vehicle.rotor_speed_max_rad_s)
        self.n_motors = vehicle.n_rotors
        self.vehicle_name = vehicle.name
        self._order_list = list(rotors_of_outputs(vehicle))
        self._order = np.array(self._order_list)

    def speeds(self, outputs: np.ndarray) -> np.ndarray:
        """Rotor speed commands (rad/s, windseek order) of PX4 motor outputs 1-N in [0, 1]."""
        n = self.n_motors
        w = np.empty(n)
        w[self._order] = self.omega_max * np.clip(np.asarray(outputs[:n], dtype=float), 0.0, 1.0)
        return w

    def outputs(self, speeds: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`speeds`: PX4 motor outputs 1-N of rotor speeds (rad/s, windseek order)."""
        return np.asarray(speeds, dtype=float)[self._order] / self.omega_max

    def check(self, controls: object, mode: int) -> Verdict:
        """Check a HIL_ACTUATOR_CONTROLS ``controls`` array (16 floats) and ``mode`` word.

        Refused: a wrong length, NaN or infinite values, motor outputs outside [0, 1], and any output
        past the vehicle's motors driven while armed (an airframe with more motors or servos).
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
        # One C-level sum instead of 16 isfinite calls: NaN and infinities carry through a sum (16 float32
        # values cannot overflow it); only a non-finite sum needs the value-by-value look.
        if not math.isfinite(sum(c)):
            bad = [i + 1 for i, v in enumerate(c) if not math.isfinite(v)]
            if bad:
                return Verdict(None, armed, "non_finite", f"NaN or infinite value on output(s) {bad}")
        nm = self.n_motors
        m, rest = c[:nm], c[nm:]
        if min(m) < -RANGE_TOL or max(m) > 1.0 + RANGE_TOL:
            return Verdict(None, armed, "out_of_range", f"motor outputs {[round(v, 3) for v in m]} outside [0, 1]")
        if armed and rest and (max(rest) > RANGE_TOL or min(rest) < -RANGE_TOL):
            outs = ", ".join(str(i + 1) for i, v in enumerate(c) if i >= nm and abs(v) > RANGE_TOL)
            return Verdict(None, armed, "wrong_airframe",
                           f"PX4 drives output(s) {outs}; windseek's vehicle {self.vehicle_name} has {nm} motors on "
                           f"outputs 1-{nm} (load its sitl/px4/windseek_*.params: CA_ROTOR_COUNT {nm}, outputs "
                           f"1-{nm} = motors)")  # fmt: skip
        if not armed:
            return Verdict(np.zeros(nm), armed)
        w = self.omega_max
        o = self._order_list
        speeds = [0.0] * nm
        for i in range(nm):
            speeds[o[i]] = w * min(max(m[i], 0.0), 1.0)
        return Verdict(np.array(speeds), armed)
