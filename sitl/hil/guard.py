"""Who flies the world in ``--px4`` mode: PX4's outputs, or windseek's safety pilot when they cannot be trusted.

Normally the world is stepped with a :class:`~sitl.world.world.RotorCommand` set from each valid
HIL_ACTUATOR_CONTROLS (:class:`~sitl.hil.motors.MotorMap`). What happens otherwise, and why:

- **An invalid output set** (NaN, a motor output outside [0, 1], outputs 5-16 driven: a wrong
  airframe, a wrong length) is dropped and counted, with one line per kind of problem. The last
  valid command is **held** for ``hold_s`` (0.5 s of simulation time): a glitch of a few frames
  must not drop a flying vehicle. If nothing valid arrives within it, a vehicle on the ground
  stops its rotors, and a vehicle in the air is **landed by windseek's built-in controller** (a
  controlled descent at the scenario's land speed, holding its horizontal position): rotors at
  zero are not safe in the air, and a command held for longer flies open loop into the wind.
- **PX4 disconnects** (TCP closed, serial silent): the runner freezes the world (no physics step
  without an answer: in lockstep, freezing time is natural) until PX4 is back
  (:mod:`sitl.hil.runner`). If the PX4 that comes back is disarmed while the vehicle is in the
  air (it rebooted), its zero outputs would drop the vehicle, so the safety pilot lands it.
- Once the safety pilot has landed and disarmed, PX4's outputs drive the rotors again.

PX4 disarming in the air by itself (a kill switch, its own failsafe) is PX4's decision and is
simulated as such: the rotors stop.

Units SI, NED, simulation time in s.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Callable
from types import SimpleNamespace
from typing import cast

import numpy as np

from sitl.autopilot.builtin import BuiltinAutopilot
from sitl.autopilot.controller import ControllerGains
from sitl.autopilot.flight_modes import FlightConfig
from sitl.hil.motors import MotorMap
from sitl.world.world import Pilot, RotorCommand, World

#: Simulation seconds an invalid output stream is bridged with the last valid command.
HOLD_S = 0.5


class ControlGuard:
    """Chooses the world's pilot (see the module docstring).

    Args:
        world: the world flown; motors: the PX4 output map; say: one-line messages.
        flight, gains: the safety pilot's flight settings (its land speed) and controller gains
            (the scenario's; the world does not carry them).
        hold_s: simulation seconds to hold the last valid command through invalid outputs.
        autopilot: its name in the messages (PX4, ArduPilot).
    """

    def __init__(self, world: World, motors: MotorMap, say: Callable[[str], None], flight: FlightConfig,
                 gains: ControllerGains, hold_s: float = HOLD_S, autopilot: str = "PX4") -> None:  # fmt: skip
        self.world = world
        self.autopilot = autopilot
        self.flight, self.gains = flight, gains
        self.motors = motors
        self.say = say
        self.hold_s = float(hold_s)
        self.command = RotorCommand(world.n_rotors)
        self.safety: BuiltinAutopilot | None = None
        self.counters: Counter[str] = Counter()
        self.armed = False  # what the autopilot's last valid output set said
        self.valid = 0
        self._bad_since = math.nan
        self._reported: set[str] = set()
        self._reconnected = False
        self._warm_up()

    def _warm_up(self) -> None:
        """Compile (or load from numba's cache) the safety pilot's kernel now, on scratch copies of the
        world's arrays: compiling it when it is needed would stall the world for tens of seconds."""
        w = self.world
        ph = w.phys
        scratch = SimpleNamespace(tick=0, wind_kernel=w.wind_kernel, phys=dataclasses.replace(
            ph, x=ph.x.copy(), flags=ph.flags.copy(), rows=ph.rows.copy(), fb=ph.fb.copy()))  # fmt: skip
        BuiltinAutopilot(self.flight, self.gains, np.zeros(3), 0.0).advance(cast(World, scratch), 1)

    @property
    def pilot(self) -> Pilot:
        """The pilot the next world step uses."""
        return self.safety if self.safety is not None else self.command

    @property
    def airborne(self) -> bool:
        return not self.world.on_ground and not self.world.crashed

    def on_controls(self, controls: object, mode: int) -> bool:
        """One HIL_ACTUATOR_CONTROLS (``controls``, ``mode``); True if it was valid."""
        v = self.motors.check(controls, mode)
        if v.speeds is None:
            return self.refuse(v.problem, v.why)
        return self.accept(v.speeds, v.armed)

    def accept(self, speeds: np.ndarray, armed: bool) -> bool:
        """A checked output set: rotor speed commands (rad/s, windseek's rotor order, finite, within the
        rotors' range) and the autopilot's armed state. Returns True."""
        self.valid += 1
        self._bad_since = math.nan
        self.armed = armed
        if self._reconnected:
            self._reconnected = False
            if not armed and self.airborne and self.safety is None:
                self._engage(f"{self.autopilot} came back disarmed with the vehicle in the air (a reboot?)")
        if self.safety is None:
            # MotorMap.check validated them (finite, in [0, omega_max]): RotorCommand.set's own checks
            # would only repeat that, once per lockstep step.
            self.command.speeds[:] = speeds
        return True

    def refuse(self, problem: str, why: str) -> bool:
        """An output set that cannot drive the rotors (``problem``: the counter's suffix; ``why``: one
        line): counted, said once per kind, and the hold limit's clock started. Returns False."""
        self.counters[f"controls_{problem}"] += 1
        if problem not in self._reported:
            self._reported.add(problem)
            self.say(f"{self.autopilot} outputs refused ({problem}) at t = {self.world.t:.2f} s: {why}; holding the "
                     f"last valid command for {self.hold_s:g} s (further ones counted)")  # fmt: skip
        if not math.isfinite(self._bad_since):
            self._bad_since = self.world.t
        return False

    def on_reconnect(self) -> None:
        """PX4 connected again after a loss: its first output set is checked for a disarmed reboot."""
        self._reconnected = True

    def before_step(self) -> None:
        """Apply the hold limit and hand the rotors back after a safety landing (once per step)."""
        w = self.world
        if math.isfinite(self._bad_since) and w.t - self._bad_since >= self.hold_s and self.safety is None:
            self._bad_since = math.nan
            if self.airborne:
                self._engage(f"no valid {self.autopilot} outputs for {self.hold_s:g} s")
            else:
                self.command.set(np.zeros(self.world.n_rotors))
                self.counters["stopped_on_ground"] += 1
                self.say(f"no valid {self.autopilot} outputs for {self.hold_s:g} s on the ground: rotors stopped")
        if self.safety is not None and not self.safety.fc.armed:
            self.safety = None
            self.command.set(np.zeros(self.world.n_rotors))
            self.say(f"safety landing done at t = {w.t:.2f} s: {self.autopilot}'s outputs drive the rotors again")

    def _engage(self, why: str) -> None:
        w = self.world
        q = w.quaternion
        yaw = math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))
        pos = w.position
        ap = BuiltinAutopilot(self.flight, self.gains, np.array([pos[0], pos[1], 0.0]), yaw)
        ap.fc.start_in_air(pos)
        ap.fc.land()
        ap.fc.update(w.t, w.phys.x, w.on_ground, w.crashed, w.slow_div * w.dt)
        self.safety = ap
        self.counters["safety_landings"] += 1
        self.say(f"{why}: windseek's built-in controller lands the vehicle from {-pos[2]:.1f} m at t = {w.t:.2f} s "
                 f"(controlled descent at {self.flight.land_speed_m_s:g} m/s)")  # fmt: skip
