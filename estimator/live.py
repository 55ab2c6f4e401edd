"""The live wind estimator on a MAVLink message stream: one synchronous, I/O-free core for every consumer.

Feed it pymavlink-like messages (``get_type()``, ``get_srcSystem()``, ``get_srcComponent()``,
fields as attributes) with :meth:`LiveCore.handle`; read :meth:`LiveCore.output` (the estimate,
only when this filter made one), :meth:`LiveCore.take_notes` (one-line events to print) and
:meth:`LiveCore.status_line`. ``windseek estimator`` wraps it with a pymavlink connection;
``estimator.worker`` runs it in a thread for asyncio programs. What it does (in full in
``estimator/README.md``, "The live core"):

- **Lock-on** to one autopilot (the first HEARTBEAT not MAV_AUTOPILOT_INVALID, of ``target_system`` if
  given); every other source is counted and ignored; rotor telemetry from ``esc_component`` if set.
- **Inputs** (``live_select``, ``mavlink_decode``) chosen after ``select_window_s`` of autopilot time and
  stated in one line; velocities wait for the IMU; ``imu_average`` IMU samples make one filter step;
  rotor speeds from ESC telemetry or the actuator outputs through ``motor_output`` and the motor lag.
- **Compass** (``compass``): the autopilot's heading is checked against its magnetometer and the
  attitude corrected by the offset, its uncertainty stated in the covariance.
- **Ground gate** (``ground_gate``), **clock resets** (a reboot restarts the filter) and the **model
  check** (``model_fit``: nothing is published until the model has been judged to fit the vehicle;
  when it does not, the wind is withheld, :meth:`LiveCore.output` returns None from then on).

Times are the autopilot's boot clock, s; wind = air-mass velocity NED, m/s; covariance (m/s)^2.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimator import mavlink_decode as dec
from estimator.compass import CompassConfig, CompassHeading
from estimator.compass_feed import CompassFeed
from estimator.config import EstimatorConfig
from estimator.ground_gate import LANDED_ON_GROUND, GroundGate, LiftOff, withheld
from estimator.live_select import InputSelection, filter_waiting_line
from estimator.model_fit import ModelFit
from estimator.motor_output import OutputMap
from estimator.px4_mag import Px4MagCalibration
from estimator.rpm_free import MotorCommandModel
from estimator.thrust_check import MAV_LANDED_STATE_IN_AIR
from estimator.ukf import WindEstimator
from vehicle.params import VehicleParams

MAV_AUTOPILOT_INVALID = 8
#: MAV_TYPE of a multirotor by its rotor count (tricopter, quadrotor, hexarotor, octorotor).
MAV_TYPE_BY_ROTORS = {3: 15, 4: 2, 6: 13, 8: 14}
#: Rotor telemetry messages (their source can be set apart: ``LiveConfig.esc_component``).
ESC_TELEMETRY = frozenset({"ESC_STATUS", "ESC_TELEMETRY_1_TO_4", "RAW_RPM", "ESC_INFO"})
MAX_NOTED_SOURCES = 8  # other systems/components noted by name; later ones are only counted


@dataclass(frozen=True)
class LiveConfig:
    """Settings of :class:`LiveCore` (see the module docstring)."""

    vehicle: VehicleParams
    estimator: EstimatorConfig | None = None  # None: the preset the vehicle file calls for (for_vehicle)
    imu_average: int = 1
    ground_gate: bool = True
    target_system: int | None = None
    esc_component: int | None = None  # rotor telemetry from this component of the target's system (None: its own)
    esc_order: tuple[int, ...] | None = None  # ESC number (0-based) -> rotor index (None: the same numbers)
    outputs: OutputMap | None = None  # actuator outputs -> rotor speeds (None: OutputMap.for_vehicle, px4)
    airframe: str | None = None  # the vehicle flown, when it is not the vehicle file's
    compass: CompassConfig = CompassConfig()  # the autopilot's heading checked against its magnetometer
    select_window_s: float = 1.0
    reset_jump_s: float = 1.0
    reset_confirm: int = 3
    max_pending_velocities: int = 30

    def __post_init__(self) -> None:
        if self.imu_average < 1:
            raise ValueError(f"imu_average = {self.imu_average}: must be an integer >= 1")
        n = self.vehicle.n_rotors
        if self.esc_order is not None and sorted(self.esc_order) != list(range(n)):
            raise ValueError(f"esc_order {self.esc_order}: must be a permutation of 0..{n - 1}")


@dataclass(frozen=True)
class LiveOutput:
    """An estimate the filter made: time (autopilot clock, s), wind NED (m/s), covariance ((m/s)^2)."""

    t: float
    wind_ned: np.ndarray
    cov_ned: np.ndarray


class LiveCore:
    """Lock-on, input selection, ground gate, clock-reset handling and the UKF on a message stream."""

    def __init__(self, config: LiveConfig) -> None:
        self.config = cfg = config
        self.outputs = cfg.outputs or OutputMap.for_vehicle(cfg.vehicle, "px4")
        self.target: tuple[int, int] | None = None
        self.autopilot_type: int | None = None
        self.counters: Counter[str] = Counter()
        self.select = InputSelection(cfg.select_window_s)
        self.landed_state: int | None = None
        self.restarts = 0
        self.model_note: str | None = None
        self.fit = ModelFit(cfg.vehicle)
        self.compass_feed = CompassFeed(cfg.compass)  # the compass check's inputs (estimator.compass_feed)
        self.compass: CompassHeading = self.compass_feed.heading
        self.autopilot_kind: int | None = None  # MAV_AUTOPILOT of the autopilot locked on to
        self._esc_order = cfg.esc_order or tuple(range(cfg.vehicle.n_rotors))
        if cfg.airframe:
            self.model_note = self._mismatch(f"the vehicle is {cfg.airframe}")
        self.t = math.nan  # newest autopilot time, s
        self.elapsed_s = 0.0  # autopilot time covered, s (continues across clock resets)
        self._notes: list[str] = []
        self._noted_sources: set[tuple[int, int]] = set()
        self._gate = GroundGate()
        self._liftoff = LiftOff()
        self._boot_ms: int | None = None
        self._behind = 0
        self.est = WindEstimator(cfg.vehicle, cfg.estimator)
        self._reset_inputs()
        if self.model_note:
            self.note(self.model_note)

    # ------------------------------------------------------------------ state
    def _reset_inputs(self) -> None:
        """Forget every held input (a fresh filter needs fresh samples)."""
        self._pending: list[tuple[float, np.ndarray]] = []
        self._imu_sum: list[np.ndarray] = []
        n = self.config.vehicle.n_rotors
        self._esc = np.full(n, np.nan)
        self._esc_seen = np.zeros(n, dtype=bool)
        self._esc_failed = np.zeros(n, dtype=bool)
        self._esc_t = -math.inf
        self._cmd: np.ndarray | None = None
        self._w_now: np.ndarray | None = None  # the rotor speeds in force (for the thrust check)
        v = self.config.vehicle
        self._motor = MotorCommandModel(v.motor_time_constant_s, v.rotor_speed_max_rad_s)

    def _restart(self, why: str) -> None:
        self.est = WindEstimator(self.config.vehicle, self.config.estimator)
        self._reset_inputs()
        self.restarts += 1
        self.counters[f"restart:{why}"] += 1

    def use_px4_raw(self, cal: Px4MagCalibration) -> None:
        """PX4's SCALED_IMU as the IMU input and the compass (``estimator.compass_feed``): its accelerometer and gyro
        without EKF2's bias estimates, which make HIGHRES_IMU agree with EKF2's heading however wrong it is."""
        self.note(self.compass_feed.set_px4_calibration(cal))
        if self.select.switch("imu", "SCALED_IMU") and any(self.est.accepted.values()):
            self._restart("imu-input")  # another IMU stream (other biases, another clock field): a fresh filter
        self.note("inputs: IMU now PX4's SCALED_IMU (no EKF2 biases taken out; the heading from its raw compass)")

    def note(self, line: str) -> None:
        """Queue a one-line event for :meth:`take_notes`."""
        self._notes.append(line)

    def take_notes(self) -> list[str]:
        """The one-line events since the last call (lock-on, inputs, other systems, clock resets)."""
        notes, self._notes = self._notes, []
        return notes

    def paused(self) -> bool:
        """True while the autopilot reports the vehicle on the ground or landing (ground gate on)."""
        return self.config.ground_gate and withheld(self.landed_state)

    def output(self) -> LiveOutput | None:
        """The current filter's estimate, or None when it has not estimated anything yet or the wind is
        withheld (the vehicle is not the model's: see the module docstring)."""
        e = self.est
        if not self.fit.publishable or e.t is None or e.accepted["imu"] == 0:
            return None
        return LiveOutput(float(e.t), e.wind_ned, e.wind_cov)

    def status_line(self) -> str:
        """What the estimator is doing, in one line (without the estimate itself)."""
        if self.target is None:
            return "waiting for an autopilot HEARTBEAT"
        if self.fit.mismatch is not None:
            return f"wind withheld: not {self.config.vehicle.name}'s model ({self.fit.mismatch.split(':')[0]})"
        if not self.select.selected:
            return f"listening for inputs ({self.select.window_s:g} s of autopilot time)"
        if self.paused():
            return "on the ground or landing: filter paused"
        if self.output() is None:
            return self.select.waiting_line() if self.select.missing() else self._waiting_detail()
        return "estimating"

    def _waiting_detail(self) -> str:
        """Every input has a message, yet nothing is published: the sample the filter lacks, or why it is held."""
        if self.fit.domain.excursion is not None:
            return f"wind withheld while {self.fit.domain.excursion}"
        return filter_waiting_line(self.est.missing_inputs(), self.select.chosen.get("rotors"), self._esc_seen,
                                   self._esc_failed)  # fmt: skip

    # ------------------------------------------------------------------ input
    def handle(self, msg: Any) -> None:
        """Take one message (any type, any source); never raises on a well-formed message object."""
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            self.counters["bad_data"] += 1
            return
        src = (int(msg.get_srcSystem()), int(msg.get_srcComponent()))
        if not self._from_target(msg, mtype, src):
            return
        t = dec.boot_time_s(msg) if mtype in dec.BOOT_CLOCK_TYPES else None
        if not self._follow_clock(msg, mtype, t):
            return
        if mtype == "HEARTBEAT":
            self._heartbeat(msg)
        elif mtype == "EXTENDED_SYS_STATE":
            self.landed_state = int(msg.landed_state)
        elif mtype == "ESC_INFO":
            self._esc_info(msg)
        elif mtype in dec.POSITION_TYPES and self.compass.declination_rad is None:
            self._say(self.compass_feed.locate(msg))
        elif mtype == "ODOMETRY":
            self.compass_feed.autopilot_yaw_sigma = dec.yaw_sigma(msg)
        group = dec.GROUP_OF.get(mtype)
        if group is None:
            return
        self.select.observe(mtype, t)
        if self.select.due(t):
            self.select.select()
            self.note(self.select.inputs_line())
        if not self.select.selected:
            return
        if self.select.claim(group, mtype):
            self.note(self.select.inputs_line() + f" ({group} now from {mtype})")
        if self.select.chosen.get(group) != mtype:
            return
        if group == "attitude":  # on the ground too: the heading is checked before take-off
            self.compass_feed.attitude(msg)
        elif group == "imu":
            self._say(self.compass_feed.magnetometer(mtype, msg, t if t is not None else self.t, self.autopilot_kind))
        paused = self.paused()
        if self.config.ground_gate:
            self._liftoff.update(self.t, self.landed_state == LANDED_ON_GROUND, self._height(mtype, msg))
        action = self._gate.admit(paused or not self._liftoff.clear)
        if action == "pause":
            self._pending.clear()
            self._imu_sum.clear()
            return
        if action == "restart":
            self._restart("lift-off")
        self._feed(group, mtype, msg, t if t is not None else self.t)

    def _height(self, mtype: str, msg: Any) -> float | None:
        """Height (m, up, any datum) from the chosen velocity message when it carries one."""
        if mtype != self.select.chosen.get("velocity"):
            return None
        if mtype == "LOCAL_POSITION_NED":
            return -float(msg.z)
        if mtype == "GLOBAL_POSITION_INT":
            return float(msg.relative_alt) * 1e-3
        return None

    def _from_target(self, msg: Any, mtype: str, src: tuple[int, int]) -> bool:
        """Lock on to the first autopilot; count and ignore every other source."""
        if self.target is None:
            if (
                mtype == "HEARTBEAT"
                and int(msg.autopilot) != MAV_AUTOPILOT_INVALID
                and (self.config.target_system is None or src[0] == self.config.target_system)
            ):
                self.target, self.autopilot_kind = src, int(msg.autopilot)
                self.note(f"autopilot system {src[0]} component {src[1]}")
                return True
            self.counters["before_lock"] += 1
            return False
        esc = self.config.esc_component
        if esc is not None and mtype in ESC_TELEMETRY:
            if src == (self.target[0], esc):
                return True
            self.counters["esc_other_component"] += 1
            return False
        if src == self.target:
            return True
        self.counters["other_system" if src[0] != self.target[0] else "other_component"] += 1
        if src[0] != self.target[0] and src not in self._noted_sources and len(self._noted_sources) < MAX_NOTED_SOURCES:
            self._noted_sources.add(src)
            self.note(f"another MAVLink system on the link: {src[0]}:{src[1]} ({mtype}); its messages are "
                       f"ignored (locked on to {self.target[0]}:{self.target[1]})")  # fmt: skip
        return False

    def _follow_clock(self, msg: Any, mtype: str, t: float | None) -> bool:
        """Track the autopilot's clock; on a reset restart the filter. False: drop this message."""
        if mtype == "SYSTEM_TIME":
            boot_ms = int(msg.time_boot_ms)
            back = self._boot_ms is not None and boot_ms < self._boot_ms - 1000.0 * self.config.reset_jump_s
            if back:
                self._clock_reset(boot_ms * 1e-3, "SYSTEM_TIME time_boot_ms went back")
            self._boot_ms = boot_ms
            if back:
                return True
        if t is None:
            return True
        if math.isfinite(self.t) and t < self.t - self.config.reset_jump_s:
            self._behind += 1
            if self._behind < self.config.reset_confirm:
                self.counters["clock_behind"] += 1
                return False
            self._clock_reset(t, f"{mtype} time stamps went back")
            return True
        self._behind = 0
        if math.isfinite(self.t) and t > self.t:
            self.elapsed_s += t - self.t
        self.t = t if not math.isfinite(self.t) else max(self.t, t)
        return True

    def _clock_reset(self, t: float, why: str) -> None:
        self.note(f"autopilot clock reset ({why}: {self.t:.3f} s -> {t:.3f} s; a reboot?): filter restarted")
        self.counters["clock_resets"] += 1
        self._restart("clock reset")
        self.select.restart_clock()
        self._behind = 0
        self._boot_ms = None  # the next SYSTEM_TIME starts the new boot (no second reset)
        self.t = t

    def _heartbeat(self, msg: Any) -> None:
        mav_type = int(msg.type)
        expected = MAV_TYPE_BY_ROTORS.get(self.config.vehicle.n_rotors, mav_type)
        if self.autopilot_type is None and mav_type != expected:  # a hexarotor's HEARTBEAT, a quad model
            from wire.dialect import mavlink

            entry = mavlink.enums["MAV_TYPE"].get(mav_type)
            name = entry.name.removeprefix("MAV_TYPE_") if entry is not None else str(mav_type)
            self.model_note = self._mismatch(f"the autopilot reports a {name} (MAV_TYPE {mav_type})")
            self.note(self.model_note)
        self.autopilot_type = mav_type

    def _mismatch(self, what: str) -> str:
        return f"model mismatch: {what}, but the force model is {self.config.vehicle.name}'s: the wind is biased"

    def _say(self, note: str | None) -> None:
        if note:
            self.note(note)

    def _esc_info(self, msg: Any) -> None:
        for i, flags in enumerate(msg.failure_flags):
            if int(msg.index) + i < len(self._esc_order):
                self._esc_failed[self._esc_order[int(msg.index) + i]] = flags != 0

    # ------------------------------------------------------------------ feeding the filter
    def _feed(self, group: str, mtype: str, msg: Any, t: float) -> None:
        est = self.est
        if group == "imu":
            self._imu(t, *dec.imu(msg))
        elif group == "attitude":
            q = dec.attitude(msg)
            if q is None:
                est._reject("attitude:bad_value")
            else:
                est.set_heading_sigma(self.compass_feed.heading_sigma())
                est.set_attitude(t, self.compass.correct(q))
        elif group == "velocity":
            v = dec.velocity(msg)
            if v is not None:
                self._pending.append((t, v))
        elif mtype in dec.COMMAND_TYPES:
            if mtype == "SERVO_OUTPUT_RAW" and int(msg.port) != 0:
                return
            cmd = self.outputs.speeds(dec.actuator_outputs(msg))
            if cmd is None:
                est._reject("rotors:bad_outputs")
            else:
                self._cmd = cmd
        else:
            self._esc_speeds(*dec.rotor_telemetry(msg), t)
        self._release_velocities()

    def _imu(self, t: float, acc: np.ndarray, gyr: np.ndarray) -> None:
        n = self.config.imu_average
        if n > 1:
            self._imu_sum.append(np.concatenate((acc, gyr)))
            if len(self._imu_sum) < n:
                return
            m = np.mean(self._imu_sum, axis=0)
            self._imu_sum.clear()
            acc, gyr = m[0:3], m[3:6]
        if self._cmd is not None:
            w = self._motor.update(t, self._cmd)  # the motor lag, advanced to this sample
            if w is not None and self.est.set_rotor_speeds(t, w):  # physical range checked first
                self._w_now = w
        self.est.imu(t, acc, gyr)
        air = self.landed_state == MAV_LANDED_STATE_IN_AIR
        est = self.est
        if self.fit.sample(t, acc, gyr, self._w_now, air, est.airspeed_body(), est.wind_sigma_h() < 1.0, est.last_nis):
            line = self.fit.mismatch
            self.model_note = line if self.model_note is None else f"{self.model_note}; {line}"
            self.note(str(line))
        elif (said := self.fit.domain.pop_note()) is not None:  # an excursion out of the identified domain
            self.note(said)

    def _esc_speeds(self, index: int, speeds: list[float], t: float) -> None:
        for i, w in enumerate(speeds):
            if index + i < len(self._esc_order):
                self._esc[self._esc_order[index + i]] = w
                self._esc_seen[self._esc_order[index + i]] = True
        # Push a complete set once per time stamp: RAW_RPM arrives one rotor per message with no
        # time of its own, so several messages share the latest time seen.
        if not self._esc_seen.all() or self._esc_failed.any() or not t > self._esc_t:
            return
        self._esc_t = t
        if self.est.set_rotor_speeds(t, self._esc):  # physical range checked first (a 1e9 burst is dropped)
            self._w_now = self._esc.copy()

    def _release_velocities(self) -> None:
        pend = self._pending
        est_t = self.est.t
        while pend and (est_t is None or pend[0][0] <= est_t + 1e-9 or len(pend) > self.config.max_pending_velocities):
            if est_t is not None and pend[0][0] > est_t + 1e-9:
                self.counters["velocity_before_imu"] += 1  # no IMU flowing: not held forever
            t, v = pend.pop(0)
            self.est.gnss_velocity(t, v)

    # ------------------------------------------------------------------ summary
    def summary(self) -> dict[str, Any]:
        """Figures for a final report (JSON-safe types; NaN where unknown)."""
        out = self.output()
        e = self.est
        sig = np.sqrt(np.maximum(np.diag(out.cov_ned), 0.0)) if out is not None else None
        return {
            "autopilot": None if self.target is None else f"{self.target[0]}:{self.target[1]}",
            "vehicle_time_s": None if not math.isfinite(self.t) else round(self.t, 3),
            "estimate_time_s": None if out is None else round(out.t, 3),
            "wind_ned_m_s": None if out is None else [round(float(v), 3) for v in out.wind_ned],
            "sigma_ned_m_s": None if sig is None else [round(float(v), 3) for v in sig],
            "inputs": dict(self.select.chosen),
            "inputs_line": self.select.inputs_line() if self.select.selected else self.status_line(),
            "model_note": self.model_note,
            "wind_withheld": self.fit.mismatch is not None,
            **self.fit.summary(),
            "accepted": dict(e.accepted),
            "rejected": dict(e.rejected),
            "counters": dict(self.counters),
            "restarts": self.restarts,
            "compass": self.compass_feed.summary(),
        }
