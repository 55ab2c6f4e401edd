"""Rotor speeds without ESC telemetry (the paper's future work): implied by the motor commands.

A flight controller always knows what it commands (PX4 ACTUATOR_OUTPUTS, ArduPilot
SERVO_OUTPUT_RAW). The rotor follows the command through the motor's first-order lag
(time constant ``tau``, s), so the implied rotor speed is the command passed through that
lag. Its error is the mismatch of the motor model (tau, the command-to-speed map) plus
everything the ESC telemetry would have seen and the command does not (voltage sag,
saturation): ``windseek estimate --no-rpm`` reports what this costs in wind accuracy.
"""

from __future__ import annotations

import math

import numpy as np


class MotorCommandModel:
    """First-order motor lag from commanded to implied rotor speeds (rad/s), exact discretization.

    Args:
        tau_s: motor time constant, s (the vehicle file's ``motor_time_constant_s``).
        w_max: rotor speed limit, rad/s (commands are clipped to [0, w_max] like the motor does).
    """

    def __init__(self, tau_s: float, w_max: float) -> None:
        if not (tau_s > 0.0 and math.isfinite(tau_s)):
            raise ValueError(f"tau_s = {tau_s}: must be finite and > 0")
        self.tau = tau_s
        self.w_max = w_max
        self.t: float | None = None
        self.speeds: np.ndarray | None = None
        self._cmd: np.ndarray | None = None

    def update(self, t: float, command: np.ndarray) -> np.ndarray | None:
        """Advance to time t (s) under the previous command, then hold ``command`` (rad/s).

        Returns the implied rotor speeds at t, or None for a rejected (non-finite, out of
        order) command.
        """
        c = np.asarray(command, dtype=float)
        if c.shape != (4,) or not np.all(np.isfinite(c)) or (self.t is not None and t <= self.t):
            return None
        c = np.clip(c, 0.0, self.w_max)
        if self.speeds is None or self.t is None:
            # Start where the rotors would be after holding the first command (hover start).
            self.speeds = c.copy()
        else:
            a = math.exp(-(t - self.t) / self.tau)
            self.speeds = c + (self.speeds - c) * a if self._cmd is None else self._cmd + (self.speeds - self._cmd) * a
        self._cmd = c
        self.t = t
        return self.speeds.copy()
