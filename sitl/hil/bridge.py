"""The world as PX4's simulator, one lockstep step at a time: plain synchronous code, no I/O.

One step is one IMU period (4 ms at the default 250 Hz IMU; two 500 Hz physics ticks): the
world advances with the current pilot's rotor commands (:class:`~sitl.hil.guard.ControlGuard`:
PX4's outputs, or the safety pilot), then everything the sensors produced becomes messages
(:mod:`sitl.hil.messages`): for PX4's simulator link HIL_GPS (when the GNSS delivered a fix),
HIL_STATE_QUATERNION (at the rate PX4 asked for) and last the step's HIL_SENSOR, whose
``time_usec`` is the IMU sample's time; for the companion programs ESC_STATUS (50 Hz), the
chemical reading and the true wind (5 Hz). The runner (:mod:`sitl.hil.runner`) sends them, waits
for PX4's HIL_ACTUATOR_CONTROLS and hands it to :meth:`HilBridge.on_controls` before the next step.

PX4 reads time 0 as "clock not set", so the world is stepped once at construction (one IMU
period on the ground, rotors off) and the first HIL_SENSOR carries 4 ms. PX4 boots disarmed, so
a scenario that starts airborne is started on the ground below its start point.

Units SI, NED world, FRD body; simulation time in s.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sitl.hil import messages as hm
from sitl.hil.guard import ControlGuard
from sitl.hil.motors import MotorMap
from sitl.hil.summary import TruthScore
from sitl.scenario import Scenario
from sitl.world.kernel import T_POS, T_TIME, T_WIND
from sitl.world.plume.part import CHEM_OUTPUT
from sitl.world.world import World

#: HIL_STATE_QUATERNION rate until PX4 asks (it asks 200 Hz at connect), and the most it gets: the
#: message is ground truth for PX4's log only, and every message costs lockstep time [Hz].
STATE_RATE_HZ = 50.0
#: Rate of the simulation-only true wind values to the companion programs [Hz].
TRUE_WIND_HZ = 5.0


@dataclass
class StepOutput:
    """What one step produced: ``to_px4`` (the simulator link; HIL_SENSOR last), ``to_companion``
    (the peripheral component's messages), ``t_us`` = the HIL_SENSOR's time (0: none sent)."""

    to_px4: list[Any] = field(default_factory=list)
    to_companion: list[Any] = field(default_factory=list)
    t_us: int = 0


def ground_start(scenario: Scenario, say: Callable[[str], None]) -> Scenario:
    """The scenario with its start on the ground (PX4 boots disarmed)."""
    st = scenario.start
    if not st.airborne:
        return scenario
    n, e, d = st.position_ned
    say(f"{scenario.name} starts airborne at {-d:g} m; with PX4 flying it starts on the ground at N {n:g} E {e:g}")
    return dataclasses.replace(scenario, start=dataclasses.replace(st, airborne=False, position_ned=(n, e, 0.0)))


class HilBridge:
    """The world, its sensors as HIL messages, PX4's outputs as rotor commands (module docstring).

    Args:
        scenario: the scenario (wind, turbulence, plume, sensors, vehicle).
        seed: overrides the scenario's seed.
        say: one-line messages (invalid outputs, safety landing, airborne start).
    """

    def __init__(self, scenario: Scenario, seed: int | None = None, say: Callable[[str], None] = print) -> None:
        sc = ground_start(scenario, say)
        self.scenario = sc
        self.world = World(sc.world_spec(), seed=seed)
        self.motors = MotorMap(self.world.vehicle)
        self.guard = ControlGuard(self.world, self.motors, say, sc.flight, sc.gains)
        self.imu_div = self.world.phys.imu_div
        self.imu_period_s = self.imu_div * self.world.dt
        self.unix0_us = int(time.time() * 1e6)  # HIL_GPS carries UNIX time (not part of the physics)
        self.state_interval_s = 1.0 / STATE_RATE_HZ
        self.truth = TruthScore(rate_hz=sc.mode_rate_hz)
        #: callables(bridge) run at every truth sample (the mode rate), after it: listeners such as a recording.
        self.step_hooks: list[Callable[[HilBridge], None]] = []
        self._truth_every = max(1, round(1.0 / (sc.mode_rate_hz * self.imu_period_s)))  # steps per truth sample
        self.steps = 0
        self._next_state = 0.0
        self._next_truth = 0.0
        self._mag: Any = None
        self._baro: Any = None
        self.world.step(self.imu_div, self.guard.pilot)
        self.world.drain()

    @property
    def t(self) -> float:
        """Simulation time, s."""
        return self.world.t

    def set_state_rate(self, interval_us: float) -> None:
        """PX4's SET_MESSAGE_INTERVAL for HIL_STATE_QUATERNION: > 0 us (at most ``STATE_RATE_HZ``), -1 off,
        0 the default."""
        if interval_us < 0:
            self.state_interval_s = float("inf")
        elif interval_us == 0:
            self.state_interval_s = 1.0 / STATE_RATE_HZ
        else:
            self.state_interval_s = max(float(interval_us) * 1e-6, 1.0 / STATE_RATE_HZ)
        self._next_state = self.world.t + self.state_interval_s - self.imu_period_s

    def on_controls(self, controls: object, mode: int) -> bool:
        """PX4's HIL_ACTUATOR_CONTROLS ``controls`` and ``mode``: the rotor command from the next step on."""
        return self.guard.on_controls(controls, mode)

    def step(self) -> StepOutput:
        """Advance one IMU period and return the messages it produced."""
        w = self.world
        self.guard.before_step()
        w.step(self.imu_div, self.guard.pilot)
        self.steps += 1
        s = w.drain()
        out = StepOutput()
        sc = self.scenario
        for g in s["gnss"]:
            out.to_px4.append(hm.hil_gps(g, sc.sensors.gnss, self.unix0_us))
        # The truth at the step's IMU sample instant (t0): the same instant as its HIL_SENSOR.
        row = w.last_truth
        t0 = float(row[T_TIME])
        if t0 >= self._next_state - 1e-9:
            self._next_state = max(self._next_state + self.state_interval_s, t0)
            out.to_px4.append(hm.hil_state_quaternion(row, sc.sensors.home))
        if self.steps % self._truth_every == 0:
            self.truth.add(t0, row[T_POS], row[T_WIND])
            for hook in self.step_hooks:
                hook(self)
        mag_new, baro_new = bool(s["mag"]), bool(s["baro"])
        if mag_new:
            self._mag = s["mag"][-1]
        if baro_new:
            self._baro = s["baro"][-1]
        for i, imu in enumerate(s["imu"]):
            first = i == 0
            out.to_px4.append(hm.hil_sensor(imu, self._mag, self._baro, mag_new and first, baro_new and first))
            out.t_us = hm.hil_time_us(imu[0])
        for t, speeds in s["esc"]:
            out.to_companion.append(hm.esc_status(t, speeds))
        for r in s.get(CHEM_OUTPUT, ()):
            out.to_companion.append(hm.named_value(r.t, "CHEM", r.value_mg_m3))
        if t0 >= self._next_truth - 1e-9:
            self._next_truth += 1.0 / TRUE_WIND_HZ
            out.to_companion.extend(hm.true_wind(t0, row[T_WIND]))
        return out

    def summary(self) -> dict[str, Any]:
        """The run's figures against the truth (see :class:`~sitl.hil.summary.TruthScore`) and the final state."""
        w = self.world
        srcs = [] if w.plume is None else [[float(v) for v in p] for p in w.plume.sources_ned]
        d: dict[str, Any] = {"scenario": self.scenario.name, "sim_time_s": round(w.t, 3)}
        d.update(self.truth.to_dict(srcs))
        d.update({"wind_true_at_vehicle_ned_m_s": [round(float(v), 3) for v in w.wind_at_vehicle],
                  "final_position_ned_m": [round(float(v), 3) for v in w.position],
                  "final_velocity_ned_m_s": [round(float(v), 3) for v in w.velocity],
                  "px4_armed": self.guard.armed, "crashed": bool(w.crashed), "on_ground": bool(w.on_ground),
                  "max_touchdown_speed_m_s": round(float(w.phys.flags[2]), 3),
                  "safety_pilot": self.guard.safety is not None})  # fmt: skip
        d.update({k: int(v) for k, v in self.guard.counters.items()})
        return d

