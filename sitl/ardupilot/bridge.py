"""The world as ArduPilot's JSON physics, one servo packet at a time: plain synchronous code, no I/O.

Each servo packet ArduPilot sends (:mod:`sitl.ardupilot.json_protocol`) advances the world by one
physics tick (1.25 ms: 800 Hz here, 500 Hz in the scenario files) with the rotor speeds its motor
outputs command (:mod:`sitl.ardupilot.motors`, checked and, when they cannot be trusted, replaced by windseek's
safety pilot: :class:`sitl.hil.guard.ControlGuard`), and answers with the state after the tick:
the IMU sample of that tick (windseek's IMU model: noise, turn-on bias, bias walk) and the truth
(position, velocity, attitude). ArduPilot's clock is the ``timestamp`` of these replies, so
ArduPilot runs in lockstep with the world, at the pace its ``--speedup`` sets.

**The IMU at the physics rate.** ArduCopter reads an IMU sample at every physics frame and refuses
to arm unless that rate is at least 1.8 times its 400 Hz main loop ("PreArm: Gyro 0 rate 500Hz <
loop ratex1.8 720Hz" at 500 Hz), so for ArduPilot the world ticks at 800 Hz, two frames per ArduCopter
loop, and the IMU is sampled at every tick (the scenario's is 250 Hz); its white noise per sample is
scaled by ``sqrt(800 / 250)`` so that its spectral density, and what any filter sees of it, stays the
scenario's. Bias and bias walk are unchanged. The finer step changes nothing physical (RK4 at 1.25 ms
against 2 ms). Why 800 and not more: each frame is two process hand-offs, which cost as much as the
frame's work, so the lockstep speed is about inversely proportional to the rate (benchmarks/README.md,
"ArduCopter in the loop": 10.5x at 1000 Hz, 12.9x at 800 Hz on this machine, same load).

**What ArduPilot simulates itself.** The JSON interface carries no GNSS, barometer or magnetometer:
ArduPilot's SITL derives them from the position and attitude it is sent, with its own ``SIM_GPS*``,
``SIM_BARO*``, ``SIM_MAG*`` noise models (windseek's parameter file leaves them at ArduPilot's
defaults). Its IMU noise is turned off there (``SIM_ACC*_RND``, ``SIM_GYR*_RND``, ``SIM_VIB_MOT_MAX``
0): the IMU is windseek's.

For the companion programs (through ArduPilot's MAVLink routing, :mod:`sitl.ardupilot.peripheral`):
the ESC model's rotor speeds (50 Hz) as ESC_TELEMETRY_1_TO_4 (ArduPilot does not know ESC_STATUS, so
it would not forward it; ESC 1-4 = windseek's rotors 1-4, as the PX4 route's ESC_STATUS), the
chemical reading and the true wind (5 Hz), as with PX4.

Units SI, NED world, FRD body; simulation time in s.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sitl.ardupilot.json_protocol import ServoPacket, state_reply
from sitl.ardupilot.motors import check_quad_x, pwm_to_speeds
from sitl.hil import messages as hm
from sitl.hil.bridge import TRUE_WIND_HZ, ground_start
from sitl.hil.guard import ControlGuard
from sitl.hil.motors import MotorMap, rotors_of_outputs
from sitl.hil.summary import TruthScore
from sitl.scenario import Scenario
from sitl.world.kernel import T_POS, T_QUAT, T_TIME, T_VEL, T_WIND
from sitl.world.plume.part import CHEM_OUTPUT
from sitl.world.world import World
from wire.dialect import mavlink

#: Physics and IMU rate for ArduPilot [Hz]: ArduCopter's pre-arm check wants the gyro at 1.8x its 400 Hz
#: main loop (``AP_InertialSensor::pre_arm_check_gyro_backend_rate_hz``), and each frame is one tick.
PHYSICS_HZ = 800.0  # >= 720 Hz (the check above); 800 = exactly two frames per 400 Hz loop


@dataclass
class FrameOutput:
    """What one frame produced: ``reply`` (the JSON state line) and ``to_companion`` (MAVLink messages)."""

    reply: bytes
    to_companion: list[Any] = field(default_factory=list)


def for_ardupilot(scenario: Scenario) -> Scenario:
    """The scenario with the physics at :data:`PHYSICS_HZ` and its IMU sampled at every tick, the IMU's
    white noise per sample scaled to keep its spectral density (module docstring)."""
    s = scenario.sensors
    k = math.sqrt(PHYSICS_HZ / s.imu.rate_hz)
    imu = dataclasses.replace(s.imu, rate_hz=PHYSICS_HZ, accel_noise_m_s2=s.imu.accel_noise_m_s2 * k,
                              gyro_noise_rad_s=s.imu.gyro_noise_rad_s * k)  # fmt: skip
    return dataclasses.replace(scenario, physics_rate_hz=PHYSICS_HZ, sensors=dataclasses.replace(s, imu=imu))


class ArduPilotBridge:
    """The world, its IMU and truth as JSON state lines, ArduPilot's PWM as rotor commands (module docstring).

    Args:
        scenario: the scenario (wind, turbulence, plume, sensors, vehicle: a quad X).
        seed: overrides the scenario's seed.
        say: one-line messages (refused outputs, safety landing, airborne start).
    """

    def __init__(self, scenario: Scenario, seed: int | None = None, say: Callable[[str], None] = print) -> None:
        sc = for_ardupilot(ground_start(scenario, say))
        self.scenario = sc
        self.world = World(sc.world_spec(), seed=seed)
        check_quad_x(self.world.vehicle)
        self.motors = MotorMap(self.world.vehicle)
        self._order = list(rotors_of_outputs(self.world.vehicle))
        self.guard = ControlGuard(self.world, self.motors, say, sc.flight, sc.gains, autopilot="ArduPilot")
        self.tick_s = self.world.dt
        self.truth = TruthScore(rate_hz=sc.mode_rate_hz)
        #: callables(bridge) run at every truth sample (the mode rate), after it: listeners such as a recording.
        self.step_hooks: list[Callable[[ArduPilotBridge], None]] = []
        self._truth_every = max(1, round(1.0 / (sc.mode_rate_hz * self.tick_s)))
        self.frames = 0
        self._esc_count = 0
        self._next_wind = 0.0
        self._last: FrameOutput | None = None
        # One tick on the ground so that the first reply has an IMU sample and a positive timestamp.
        self._imu = self._advance()

    @property
    def t(self) -> float:
        """Simulation time, s."""
        return self.world.t

    def _advance(self) -> tuple[float, Any, Any]:
        w = self.world
        self.guard.before_step()
        w.step(1, self.guard.pilot)
        s = w.drain()
        self._pending = s
        return s["imu"][-1] if s["imu"] else self._imu

    def on_servos(self, pkt: ServoPacket) -> bool:
        """Apply a servo packet's motor outputs (from the next tick on); False if they were refused."""
        r = pwm_to_speeds(pkt.pwm, self._order, self.motors.omega_max)
        if isinstance(r, str):
            return self.guard.refuse("out_of_range", r)
        speeds, armed = r
        return self.guard.accept(np.array(speeds), armed)

    def step(self) -> FrameOutput:
        """Advance one physics tick; the JSON state after it and the companions' messages."""
        self._imu = self._advance()
        self.frames += 1
        w = self.world
        row = w.last_truth
        t, acc, gyr = self._imu
        tr = row.tolist()  # Python floats format several times faster than numpy scalars
        out = FrameOutput(state_reply(tr[T_TIME], gyr.tolist(), acc.tolist(), tr[T_POS], tr[T_VEL], tr[T_QUAT]))
        s = self._pending
        for _te, speeds in s["esc"]:
            out.to_companion.append(self._esc_telemetry(speeds))
        for r in s.get(CHEM_OUTPUT, ()):
            out.to_companion.append(hm.named_value(r.t, "CHEM", r.value_mg_m3))
        t0 = float(row[T_TIME])
        if self.frames % self._truth_every == 0:
            self.truth.add(t0, row[T_POS], row[T_WIND])
            for hook in self.step_hooks:
                hook(self)
        if t0 >= self._next_wind - 1e-9:
            self._next_wind += 1.0 / TRUE_WIND_HZ
            out.to_companion.extend(hm.true_wind(t0, row[T_WIND]))
        self._last = out
        return out

    def _esc_telemetry(self, speeds_rad_s: Any) -> Any:
        """ESC_TELEMETRY_1_TO_4 of measured rotor speeds (ESC 1-4 = windseek's rotors 1-4, rpm), as the
        peripheral's ESC telemetry (ArduPilot forwards it; it does not know ESC_STATUS)."""
        self._esc_count = (self._esc_count + 1) & 0xFFFF
        rpm = [max(0, min(65535, int(round(float(w) * hm.RAD_S_TO_RPM)))) for w in speeds_rad_s]
        return mavlink.MAVLink_esc_telemetry_1_to_4_message([0] * 4, [0] * 4, [0] * 4, [0] * 4, rpm,
                                                            [self._esc_count] * 4)  # fmt: skip

    def repeat(self) -> bytes:
        """The last reply again (ArduPilot resent a frame it had no answer to): the world does not move."""
        return self._last.reply if self._last is not None else self.step().reply

    def summary(self) -> dict[str, Any]:
        """The run's figures against the truth and the final state."""
        w = self.world
        srcs = [] if w.plume is None else [[float(v) for v in p] for p in w.plume.sources_ned]
        d: dict[str, Any] = {"scenario": self.scenario.name, "sim_time_s": round(w.t, 3), "frames": self.frames}
        d.update(self.truth.to_dict(srcs))
        d.update({"wind_true_at_vehicle_ned_m_s": [round(float(v), 3) for v in w.wind_at_vehicle],
                  "final_position_ned_m": [round(float(v), 3) for v in w.position],
                  "final_velocity_ned_m_s": [round(float(v), 3) for v in w.velocity],
                  "ardupilot_armed": self.guard.armed, "crashed": bool(w.crashed), "on_ground": bool(w.on_ground),
                  "max_touchdown_speed_m_s": round(float(w.phys.flags[2]), 3),
                  "safety_pilot": self.guard.safety is not None})  # fmt: skip
        d.update({k: int(v) for k, v in self.guard.counters.items()})
        return d
