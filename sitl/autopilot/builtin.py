"""The built-in autopilot as a :class:`~sitl.world.world.Pilot`: PX4-like flight modes at the slow-tick
rate on the true state (it stands in for an autopilot and its navigation filter), and the cascaded
controller every physics tick through the fused fast path (:mod:`sitl.autopilot.fused`).

Units SI, NED world, FRD body; gains by name (:class:`~sitl.autopilot.controller.ControllerGains`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from sitl.autopilot.controller import GAIN_NAMES, N_CTRL_STATE, ControllerGains
from sitl.autopilot.flight_modes import FlightConfig, FlightController
from sitl.autopilot.fused import advance_controlled
from sitl.world.kernel import compiled_entry
from sitl.world.world import World
from vehicle.params import MAX_ROTORS

#: How long the captive trim of an airborne start runs (simulated s at t = 0; time does not advance).
TRIM_S = 6.0
#: Gain of the captive trim's velocity-integrator update (1/s).
TRIM_GAIN = 2.0


class BuiltinAutopilot:
    """Flight modes (:class:`FlightController`, ``fc``) + controller gains and memory.

    Args:
        flight: mode-level limits (take-off speed, land speed, timeouts, ...).
        gains: controller gains and limits.
        home_ned: home point (m, NED) before the first arming; yaw_rad: initial yaw.
    """

    def __init__(self, flight: FlightConfig, gains: ControllerGains, home_ned: np.ndarray, yaw_rad: float) -> None:
        self.fc = FlightController(flight, home_yaw=yaw_rad)
        self.fc.home = np.array(home_ned, dtype=float)
        self.gains = gains.as_array()
        self.cs = np.zeros(N_CTRL_STATE)
        self.accel_sp = np.zeros(3)
        #: An excitation added to the squared rotor-speed commands from physics tick ``excitation_tick0``
        #: on (see :func:`sitl.autopilot.fused.advance_controlled`); none by default.
        self.excitation = np.zeros((0, MAX_ROTORS))
        self.excitation_tick0 = 0
        self._entry: Callable[..., int] = advance_controlled
        self._entry_world: World | None = None

    # ------------------------------------------------------------------ Pilot
    def on_slow_tick(self, world: World) -> None:
        """The mode logic at the slow-tick rate, on the true state."""
        self.fc.update(world.t, world.phys.x, world.on_ground, world.crashed, world.slow_div * world.dt)

    def advance(self, world: World, n: int) -> int:
        ph = world.phys
        args = (n, world.tick, ph.dt, ph.x, ph.flags, ph.params, ph.crash_speed, ph.imu_div, ph.rows, ph.fb,
                world.wind_kernel, ph.obstacles, self.fc.sp, self.gains, self.cs, self.accel_sp, self.excitation,
                self.excitation_tick0)  # fmt: skip
        if self._entry_world is not world:
            # The argument types are fixed per world (its arrays and tuples; the excitation is always a 2-D float
            # array): the compiled loop is looked up once and called directly (see compiled_entry).
            self._entry, self._entry_world = compiled_entry(advance_controlled, args), world
        return int(self._entry(*args))

    def set_excitation(self, dw2: np.ndarray, tick0: int) -> None:
        """Add ``dw2`` (K, N rotors; rad^2/s^2) to the squared rotor-speed commands of physics ticks
        ``tick0 .. tick0 + K - 1`` (the system identification's input, :mod:`identify.fly_world`)."""
        table = np.zeros((dw2.shape[0], MAX_ROTORS))
        table[:, : dw2.shape[1]] = dw2
        self.excitation = table
        self.excitation_tick0 = int(tick0)

    # ------------------------------------------------------------------ set-up
    def start_hovering(self, world: World) -> None:
        """Initial condition of an airborne start: armed, holding, trimmed for the wind at the start.

        The trim is found "captive": the vehicle is held at its start position and velocity (like
        a test stand) for ``TRIM_S`` simulated seconds at t = 0 while attitude, rotor speeds and
        controller integrators settle. Time does not advance and no sensor samples are produced,
        so a run starts in steady hover instead of being blown off its point.
        """
        ph = world.phys
        world.set_hover_rotors()
        ph.flags[0] = 0.0
        self.fc.start_in_air(ph.x[0:3])
        slow_dt = world.slow_div * world.dt
        self.fc.update(0.0, ph.x, False, False, slow_dt)
        hold = ph.x[0:6].copy()
        rows = np.zeros((2, ph.rows.shape[1]))
        lim = self.gains[GAIN_NAMES.index("vel_int_lim")]
        for _ in range(int(round(TRIM_S / ph.dt))):
            advance_controlled(1, 0, ph.dt, ph.x, ph.flags, ph.params, ph.crash_speed, ph.imu_div, rows, ph.fb,
                               world.wind_kernel, ph.obstacles, self.fc.sp, self.gains, self.cs,
                               self.accel_sp, np.zeros((0, MAX_ROTORS)), 0)  # fmt: skip
            # The stand measures the acceleration it prevents and trims the velocity-loop
            # integrators against it, so the release finds the vehicle already leaning in.
            accel = (ph.x[3:6] - hold[3:6]) / ph.dt
            self.cs[0:3] = np.clip(self.cs[0:3] - TRIM_GAIN * accel * ph.dt, -lim, lim)
            ph.x[0:6] = hold

    # ------------------------------------------------------------------ live tuning
    def gain(self, name: str) -> float:
        """Current value of a controller gain (see :class:`ControllerGains`)."""
        return float(self.gains[GAIN_NAMES.index(name)])

    def set_gain(self, name: str, value: float) -> None:
        """Change a controller gain in flight (parameter protocol). ValueError if unknown/bad."""
        if name not in GAIN_NAMES:
            raise ValueError(f"unknown gain {name!r}; allowed: {', '.join(GAIN_NAMES)}")
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"gain {name} = {value!r}: must be finite and >= 0")
        self.gains[GAIN_NAMES.index(name)] = float(value)
