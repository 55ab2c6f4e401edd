"""ArduCopter's servo outputs to windseek's rotor speeds: motor order, PWM range and thrust curve.

**Motor order.** ArduCopter's quad X (``FRAME_CLASS 1``, ``FRAME_TYPE 1``;
``libraries/AP_Motors/AP_MotorsMatrix.cpp``, ``MOTOR_FRAME_TYPE_X``) numbers its motors 1 front right
(45 deg, CCW), 2 rear left (-135 deg, CCW), 3 front left (-45 deg, CW), 4 rear right (135 deg, CW),
on servo outputs 1-4 (``SERVOi_FUNCTION`` 33-36). That is PX4's generic quad X numbering too, so
the vehicle file's ``px4_outputs`` serve both autopilots (:func:`sitl.hil.motors.rotors_of_outputs`):
output ``i`` drives windseek rotor ``(0, 2, 3, 1)[i]`` and the spin directions agree. Only quad X
vehicles are mapped; ArduCopter's hexa X numbers its motors unlike PX4's.

**PWM.** An output of ``pwm`` microseconds (:func:`pwm_to_speeds`) is the ESC command ``a = (pwm - MOT_PWM_MIN) /
(MOT_PWM_MAX - MOT_PWM_MIN)`` (1000-2000 us here), clipped to [0, 1]; the ESC commands the rotor
speed ``omega = omega_max * a`` (the same linear speed command as windseek's PX4 bridge,
:mod:`sitl.hil.motors`), and the motor follows with its first-order lag. ``pwm`` 0 (a channel
ArduPilot has not started) is 0. Values more than :data:`PWM_SLACK_US` outside the range are refused.

**Thrust curve.** ArduCopter models a motor's thrust over its range ``[MOT_SPIN_MIN, MOT_SPIN_MAX]``
of the ESC command (``AP_Motors_Thrust_Linearization.cpp``): with ``r = (a - spin_min) / (spin_max -
spin_min)``, thrust / full thrust ``= (1 - e) r + e r^2`` (``e`` = ``MOT_THST_EXPO``), and it inverts
that to linearise its loops. windseek's rotor gives ``T(a) = A a^2 + B a`` (``A = kt2 omega_max^2``,
``B = kt1 omega_max``, the truth's static thrust fit, :func:`vehicle.truth.with_control_figures`).
Substituting ``a = spin_min + d r`` (``d = spin_max - spin_min``), ``T - T(spin_min)`` is exactly
quadratic in ``r``, with ``e = A d / (2 A spin_min + B + A d)``. ArduCopter's model has no thrust at
``r = 0`` where the rotor has ``T(spin_min)`` (2 % of full thrust here); the hover throttle
``MOT_THST_HOVER`` is measured on ArduCopter's scale, ``(T_hover - T(spin_min)) / (T(spin_max) -
T(spin_min))``. :func:`ardupilot_figures` computes both; the shipped parameter file carries them.

Units SI; rotor speeds rad/s; PWM in microseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

from sitl.hil.motors import rotors_of_outputs
from vehicle.params import VehicleParams

#: ArduCopter's defaults (``MOT_PWM_MIN/MAX`` as the parameter file sets them, ``MOT_SPIN_*`` defaults).
PWM_MIN, PWM_MAX = 1000, 2000
SPIN_ARM, SPIN_MIN, SPIN_MAX = 0.10, 0.15, 0.95
#: A motor PWM this far outside [PWM_MIN, PWM_MAX] is refused; within it, it is clipped [us].
PWM_SLACK_US = 100
#: Above PWM_MIN by more than this, a motor is spinning: ArduCopter is armed (it idles at MOT_SPIN_ARM) [us].
ARMED_ABOVE_US = 20


@dataclass(frozen=True)
class ArduCopterFigures:
    """What ArduCopter's parameters must say about a windseek quad (module docstring): ``thst_expo``
    (``MOT_THST_EXPO``), ``thst_hover`` (``MOT_THST_HOVER``), ``hover_esc`` (the ESC command that
    hovers, in [0, 1]), ``thrust_to_weight`` (at ``MOT_SPIN_MAX``)."""

    thst_expo: float
    thst_hover: float
    hover_esc: float
    thrust_to_weight: float


def check_quad_x(vehicle: VehicleParams) -> None:
    """Refuse a vehicle ArduCopter's quad X cannot fly in windseek (one line)."""
    if vehicle.n_rotors != 4:
        raise ValueError(f"vehicle {vehicle.name}: {vehicle.n_rotors} rotors; windseek maps ArduCopter's quad X "
                         "(FRAME_CLASS 1, FRAME_TYPE 1) only")  # fmt: skip
    rotors_of_outputs(vehicle)


def ardupilot_figures(vehicle: VehicleParams, spin_min: float = SPIN_MIN, spin_max: float = SPIN_MAX
                      ) -> ArduCopterFigures:  # fmt: skip
    """``MOT_THST_EXPO`` and ``MOT_THST_HOVER`` of ``vehicle`` (zero airspeed; module docstring)."""
    c = vehicle.control
    w_max = float(vehicle.rotor_speed_max_rad_s)
    a, b = c["kt2"] * w_max**2, c["kt1"] * w_max  # T(u) = a u^2 + b u [N], u = ESC command

    def thrust(u: float) -> float:
        return a * u * u + b * u

    d = spin_max - spin_min
    expo = a * d / (2 * a * spin_min + b + a * d)
    t_hover = vehicle.mass_kg * vehicle.gravity_m_s2 / vehicle.n_rotors
    hover = (t_hover - thrust(spin_min)) / (thrust(spin_max) - thrust(spin_min))
    hover_esc = (-b + (b * b + 4 * a * t_hover) ** 0.5) / (2 * a) if a > 0 else t_hover / b
    return ArduCopterFigures(thst_expo=float(expo), thst_hover=float(hover), hover_esc=float(hover_esc),
                             thrust_to_weight=float(thrust(spin_max) / t_hover))  # fmt: skip


def pwm_to_speeds(pwm: tuple[int, ...], rotor_of_output: list[int], omega_max: float, pwm_min: int = PWM_MIN,
                  pwm_max: int = PWM_MAX) -> tuple[list[float], bool] | str:  # fmt: skip
    """Rotor speed commands (rad/s, windseek's rotor order) of the motor outputs and whether ArduCopter is
    armed (a motor above ``pwm_min``: it idles at ``MOT_SPIN_ARM``), or a one-line reason why the packet
    cannot drive the rotors. ``rotor_of_output[i]``: the rotor output ``i`` drives. Channels past the motors
    are not read: on ArduCopter they carry whatever their ``SERVOn_FUNCTION`` says (RC pass-through, trim).
    Plain Python: this runs once per frame, and numpy's call overhead on four numbers is more than the work."""
    n = len(rotor_of_output)
    m = pwm[:n]
    lo, hi = pwm_min - PWM_SLACK_US, pwm_max + PWM_SLACK_US
    if not all(lo <= p <= hi or p == 0 for p in m):
        bad = [i + 1 for i, p in enumerate(m) if p != 0 and not lo <= p <= hi]
        return (f"motor output(s) {bad} at {[m[i - 1] for i in bad]} us, outside {pwm_min}-{pwm_max} us by more "
                f"than {PWM_SLACK_US} us")  # fmt: skip
    k = omega_max / float(pwm_max - pwm_min)
    speeds = [0.0] * n
    for i, p in enumerate(m):
        if p > pwm_min:
            speeds[rotor_of_output[i]] = omega_max if p >= pwm_max else (p - pwm_min) * k
    return speeds, max(m) > pwm_min + ARMED_ABOVE_US
