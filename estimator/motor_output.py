"""Rotor speeds from an autopilot's actuator outputs, when there is no ESC telemetry.

Real PX4 vehicles without ESC telemetry (and PX4 SIH) publish no ESC_STATUS and no RAW_RPM, but
they publish what they command: ACTUATOR_OUTPUT_STATUS (float values in the output driver's
units) or SERVO_OUTPUT_RAW (PWM us). :class:`OutputMap` turns one such message into commanded
rotor speeds (rad/s, the project's rotor order); ``estimator.rpm_free.MotorCommandModel`` then
passes them through the motor's first-order lag (the vehicle file's ``motor_time_constant_s``).

The map, step by step (every value is a field of :class:`OutputMap`, set per vehicle/autopilot):

1. Output number -> rotor: ``order[k]`` is the rotor index (0-based) of output k + 1. The
   project's rotors (``vehicle.params``): 1 front-right, 2 rear-right, 3 rear-left, 4 front-left.
   PX4 quad-X (airframe 4001_quad_x, control allocation CA_ROTOR0..3 positions PX/PY in FRD):
   motor 1 front-right (1, 1), 2 rear-left (-1, -1), 3 front-left (1, -1), 4 rear-right (-1, 1),
   hence :data:`PX4_QUAD_X` = (0, 2, 3, 1). The windseek SITL numbers its outputs like its rotors.
   With a vehicle file the PX4 order is the file's ``[frame] px4_outputs`` (:func:`px4_order`):
   PX4_QUAD_X for the paper's quad X, the identity for px4-sih-quadx (its rotors are in PX4's order).
2. Raw value -> normalized command u in [0, 1]: u = (raw - raw_min) / (raw_max - raw_min),
   clipped at 1. PX4 writes its output driver's values: PWM 1000-2000 us by default
   (PWM_MAIN_MINn/MAXn), and the same 1000-2000 range in SITL and SIH (``pwm_out_sim``). A value
   below raw_min (PX4's disarmed value, 900 us; 0 = unused channel) means the motor is stopped.
3. u -> rotor speed. PX4 maps the allocator's relative thrust T to u through THR_MDL_FAC = f
   (T = f u^2 + (1 - f) u; ``FunctionMotors::updateValues``). Two documented choices:
   - ``thr_mdl_fac = None`` (default): rotor speed linear in u, omega = omega_min + u (omega_max
     - omega_min): an ESC that sets speed in proportion to its command, the usual first
     approximation. With omega_min = 0 it is exactly the windseek SITL's encoding
     (``sitl/link/telemetry.py``: raw = 1000 + 1000 omega / omega_max).
   - ``thr_mdl_fac = f``: thrust follows PX4's model and thrust ~ omega^2, so
     omega = sqrt(omega_min^2 + T (omega_max^2 - omega_min^2)). Use the vehicle's THR_MDL_FAC.
   omega_min is the armed idle speed at u = 0, omega_max the speed at u = 1 (rad/s).

This is the paper's "future work": the error of the motor model (tau, the command-to-speed
map, voltage sag) goes into the wind estimate; ``windseek estimate --no-rpm`` shows the cost.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vehicle.params import VehicleParams

#: Output / ESC number (0-based) -> rotor index (0-based): the windseek SITL, identity.
SITL_ORDER: tuple[int, ...] = (0, 1, 2, 3)
#: PX4 quad-X: motor 1 front-right, 2 rear-left, 3 front-left, 4 rear-right (CA_ROTOR0..3).
PX4_QUAD_X: tuple[int, ...] = (0, 2, 3, 1)
#: ArduCopter's quad X numbers its motors as PX4's does (AP_MotorsMatrix MOTOR_FRAME_TYPE_X).
MOTOR_ORDERS = {"sitl": SITL_ORDER, "px4": PX4_QUAD_X, "ardupilot": PX4_QUAD_X}


def px4_order(params: VehicleParams) -> tuple[int, ...]:
    """Rotor index of each PX4 output from the vehicle file's ``[frame] px4_outputs`` (PX4_QUAD_X for the
    paper's quad X; identity for a vehicle listed in PX4's own order, such as px4-sih-quadx); PX4_QUAD_X when
    the file's list does not number every rotor once."""
    outs = tuple(params.px4_outputs)
    if sorted(outs) != list(range(params.n_rotors)):
        return PX4_QUAD_X
    order = [0] * len(outs)
    for rotor, out in enumerate(outs):
        order[out] = rotor
    return tuple(order)


@dataclass(frozen=True)
class OutputMap:
    """Actuator outputs -> commanded rotor speeds (see the module docstring for each field)."""

    order: tuple[int, ...] = PX4_QUAD_X
    raw_min: float = 1000.0  # raw value at u = 0 (PWM us)
    raw_max: float = 2000.0  # raw value at u = 1
    omega_min: float = 100.0  # rotor speed at u = 0, rad/s (armed idle)
    omega_max: float = 600.0  # rotor speed at u = 1, rad/s
    thr_mdl_fac: float | None = None  # None: speed linear in u; f in [0, 1]: PX4's thrust model

    def __post_init__(self) -> None:
        if sorted(self.order) != list(range(len(self.order))):
            raise ValueError(f"output order {self.order}: must be a permutation of 0..{len(self.order) - 1}")
        if not (math.isfinite(self.raw_min) and math.isfinite(self.raw_max) and self.raw_max > self.raw_min):
            raise ValueError(f"output range {self.raw_min}..{self.raw_max}: needs finite min < max")
        if not 0.0 <= self.omega_min < self.omega_max:
            raise ValueError(f"rotor speeds {self.omega_min}..{self.omega_max} rad/s: needs 0 <= min < max")
        if self.thr_mdl_fac is not None and not 0.0 <= self.thr_mdl_fac <= 1.0:
            raise ValueError(f"thr_mdl_fac = {self.thr_mdl_fac}: must be in [0, 1] (PX4 THR_MDL_FAC)")

    @classmethod
    def for_vehicle(cls, params: VehicleParams, profile: str = "px4", thr_mdl_fac: float | None = None,
                    raw_range: tuple[float, float] = (1000.0, 2000.0)) -> OutputMap:  # fmt: skip
        """``px4``: the vehicle file's PX4 output order (:func:`px4_order`), omega_min..omega_max of the vehicle
        file; ``sitl``: the windseek SITL's outputs (its rotor order, 0..omega_max linear); ``ardupilot``:
        ArduCopter's quad X outputs (PX4's order) with windseek's ESC under ArduPilot (0..omega_max linear
        over MOT_PWM_MIN..MAX, :mod:`sitl.ardupilot.motors`)."""
        if profile not in MOTOR_ORDERS:
            raise ValueError(f"motor order {profile!r}: choose one of {', '.join(MOTOR_ORDERS)}")
        w_min = 0.0 if profile in ("sitl", "ardupilot") else params.rotor_speed_min_rad_s
        order = px4_order(params) if profile in ("px4", "ardupilot") else MOTOR_ORDERS[profile]
        return cls(order, raw_range[0], raw_range[1], w_min, params.rotor_speed_max_rad_s, thr_mdl_fac)

    def speed(self, u: float) -> float:
        """Rotor speed (rad/s) for the normalized command u in [0, 1]."""
        if self.thr_mdl_fac is None:
            return self.omega_min + u * (self.omega_max - self.omega_min)
        f = self.thr_mdl_fac
        rel_thrust = f * u * u + (1.0 - f) * u
        return math.sqrt(self.omega_min**2 + rel_thrust * (self.omega_max**2 - self.omega_min**2))

    def speeds(self, raw_outputs: Sequence[float]) -> np.ndarray | None:
        """Commanded rotor speeds (rad/s, rotor order) from raw outputs (output 1 first); None when a
        motor output is missing or not finite."""
        n = len(self.order)
        if len(raw_outputs) < n:
            return None
        w = np.zeros(n)
        for k in range(n):
            raw = float(raw_outputs[k])
            if not math.isfinite(raw):
                return None
            if raw < self.raw_min:
                continue  # disarmed or unused: the motor is stopped
            u = min((raw - self.raw_min) / (self.raw_max - self.raw_min), 1.0)
            w[self.order[k]] = self.speed(u)
        return w

    def raw_outputs(self, omega_rotor: Sequence[float]) -> list[float]:
        """The inverse: raw outputs (output 1 first) that command these rotor speeds (rad/s, rotor
        order), clipped to the map's range. For tests and simulated autopilots."""
        out = [0.0] * len(self.order)
        for k, r in enumerate(self.order):
            w = min(max(float(omega_rotor[r]), self.omega_min), self.omega_max)
            if self.thr_mdl_fac is None:
                u = (w - self.omega_min) / (self.omega_max - self.omega_min)
            else:
                rel = (w * w - self.omega_min**2) / (self.omega_max**2 - self.omega_min**2)
                f = self.thr_mdl_fac
                u = rel if f == 0.0 else (-(1.0 - f) + math.sqrt((1.0 - f) ** 2 + 4.0 * f * rel)) / (2.0 * f)
            out[k] = self.raw_min + u * (self.raw_max - self.raw_min)
        return out
