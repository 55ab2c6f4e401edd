"""The loop that makes windseek PX4's simulator: lockstep with PX4 SITL, real time with HITL.

States (:class:`Sync`):

- ``waiting``: no PX4 connected. The world is frozen (no physics step without PX4's answer);
  after a connection loss it stays frozen until PX4 connects again.
- ``freewheel``: PX4 connected but has not answered yet (it boots, and its controllers publish no
  output before their first run). Steps run at real time, sensors go out, nothing is awaited.
- ``lockstep``: PX4 answered with ``flags`` bit 0 set (a lockstep SITL build). Every step sends the
  step's HIL_SENSOR and **waits for a HIL_ACTUATOR_CONTROLS stamped at or after that sensor time**
  before the next physics step. The wait is bounded (``answer_timeout_s`` wall seconds): on a
  timeout (PX4 stalled, an answer lost) the runner says so, counts it and steps on with the last
  outputs, so a lost answer cannot deadlock both sides. Paced at ``speed`` simulated seconds per
  wall second, or as fast as PX4 answers with ``speed = 0`` (``--px4-free``).
- ``realtime``: PX4 answers without the lockstep flag (HITL on a flight controller, whose clock is
  its own, or a SITL build without lockstep). Steps run at real time; outputs apply as they come.
  If they stop for ``realtime_timeout_s`` the world freezes until they come back.

Time: the HIL clock is the simulation time (:func:`sitl.hil.messages.hil_time_us`); in lockstep
it is PX4's clock too. ``wall`` names wall-clock seconds.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

from sitl.hil.bridge import HilBridge
from sitl.hil.frames import Controls
from sitl.hil.motors import FLAG_LOCKSTEP
from sitl.hil.px4_link import SimLink, TcpSimLink

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MSG_ID_HIL_STATE_QUATERNION = 115
MAV_AUTOPILOT_INVALID = 8
#: Lag behind the pacing clock that is forgiven (the clock is re-anchored and it is counted) [sim s].
MAX_LAG_S = 0.5
#: Lockstep steps between two checks for a PX4 that reconnected while the old socket is still open.
RECONNECT_CHECK_STEPS = 250
#: Lockstep steps between two services of the peripheral link (5 = 20 ms of simulation time).
SERVICE_STEPS = 5


class Sync(Enum):
    WAITING = "waiting"
    FREEWHEEL = "freewheel"
    LOCKSTEP = "lockstep"
    REALTIME = "realtime"


@dataclass
class HilOptions:
    """speed: sim s per wall s in lockstep (0 = as fast as PX4 answers); answer_timeout_s: wall s to
    wait for a lockstep answer; realtime_timeout_s: wall s of silence that freezes a real-time run."""

    speed: float = 1.0
    answer_timeout_s: float = 2.0
    realtime_timeout_s: float = 0.5

    def validate(self) -> None:
        if not (math.isfinite(self.speed) and self.speed >= 0):
            raise ValueError(f"speed {self.speed}: must be >= 0 (0 = as fast as PX4 answers)")
        for name in ("answer_timeout_s", "realtime_timeout_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} {v}: must be > 0")


class HilRunner:
    """The world (``bridge``), the link to PX4 (``link``) and the peripheral component (``peripheral``,
    or None) in one loop (see the module docstring); ``say`` gets one-line messages."""

    def __init__(self, bridge: HilBridge, link: SimLink, peripheral: Any, options: HilOptions,
                 say: Callable[[str], None]) -> None:  # fmt: skip
        options.validate()
        self.bridge = bridge
        self.link = link
        self.peripheral = peripheral
        self.options = options
        self.say = say
        self.state = Sync.WAITING
        self.counters: Counter[str] = Counter()
        self.answered_us = 0
        self.px4_system: int | None = None
        self.lockstep_sim_s = 0.0
        #: Wall seconds of lockstep steps: the world step and PX4's answer (throughput), and with the pacing
        #: sleep too (the pace the run actually went at: at --speed 1 about 1 s per simulated s).
        self.lockstep_wall_s = 0.0
        self.lockstep_paced_wall_s = 0.0
        #: Wall seconds of lockstep spent in windseek (world step, messages, sending) and waiting for PX4.
        self.world_wall_s = 0.0
        self.px4_wall_s = 0.0
        #: CPU seconds of this process in lockstep (the machine's load inflates it less than wall time),
        #: sampled every SERVICE_STEPS steps (the CPU clock is a system call, not worth one per step).
        self.world_cpu_s = 0.0
        self._cpu_mark = 0.0
        self._stop = threading.Event()
        self._connected_once = False
        self._frozen = False
        self._last_answer_wall = -math.inf
        self._wall0 = self._sim0 = 0.0
        self._timeouts_said = 0
        #: callables(message) run for every message the peripheral (or, in HITL, PX4's link) passes on, after
        #: the truth scored it: listeners such as a recording.
        self.rx_hooks: list[Callable[[Any], None]] = []

    # ------------------------------------------------------------------ control
    def stop(self) -> None:
        """Ask the loop to return (thread-safe; the signal handler's)."""
        self._stop.set()

    def _anchor(self) -> None:
        self._wall0 = time.monotonic()
        self._sim0 = self.bridge.t

    def serve(self, duration_s: float | None = None, wall_limit_s: float | None = None) -> None:
        """Run until :meth:`stop`, ``duration_s`` of simulation time, or ``wall_limit_s`` wall seconds."""
        b = self.bridge
        t_end = math.inf if duration_s is None else b.t + duration_s
        wall_end = math.inf if wall_limit_s is None else time.monotonic() + wall_limit_s
        self._anchor()
        while not self._stop.is_set() and b.t < t_end - 1e-9 and time.monotonic() < wall_end:
            if not self.link.connected:
                self._lost()
                if self.link.accept(0.05):
                    self._connected()
                self._service()
                continue
            if self.state == Sync.WAITING:
                self._connected()
            if self.state == Sync.LOCKSTEP:
                self._lockstep_step()
            else:
                self._realtime_step()

    # ------------------------------------------------------------------ connection
    def _connected(self) -> None:
        self.state = Sync.FREEWHEEL
        self._frozen = False
        self._anchor()
        peer = getattr(self.link, "peer", None)
        where = f" from {peer[0]}:{peer[1]}" if peer else ""
        if self._connected_once:
            self.counters["reconnects"] += 1
            self.bridge.guard.on_reconnect()
            self.say(f"PX4 connected again{where} at t = {self.bridge.t:.2f} s: resuming")
        else:
            self.say(f"PX4 connected on {self.link.name}{where}: free-running until its first actuator outputs")
        self._connected_once = True

    def _lost(self) -> None:
        if self.state == Sync.WAITING:
            return
        self.state = Sync.WAITING
        self.counters["disconnects"] += 1
        w = self.bridge.world
        where = "on the ground" if w.on_ground else f"in the air at {-w.position[2]:.1f} m"
        self.say(f"PX4 disconnected at t = {w.t:.2f} s ({where}): the world is frozen until PX4 connects again")

    # ------------------------------------------------------------------ steps
    def _send(self, out: Any) -> None:
        self.link.send(out.to_px4)
        # The peripheral speaks as a component of PX4's system: not before its id is known.
        if self.peripheral is not None and out.to_companion and self.px4_system is not None:
            self.peripheral.send(out.to_companion)

    def _lockstep_step(self) -> None:
        b = self.bridge
        w0 = time.monotonic()
        out = b.step()
        self._send(out)
        w1 = time.monotonic()
        if out.t_us:
            self._await(out.t_us)
        w2 = time.monotonic()
        self.world_wall_s += w1 - w0
        self.px4_wall_s += w2 - w1
        self.lockstep_sim_s += b.imu_period_s
        self.lockstep_wall_s += w2 - w0
        if b.steps % SERVICE_STEPS == 0:
            self._service()
            c = time.process_time()
            self.world_cpu_s += c - self._cpu_mark
            self._cpu_mark = c
        if b.steps % RECONNECT_CHECK_STEPS == 0 and isinstance(self.link, TcpSimLink) and self.link.pending():
            self.link.accept(0.0)  # a restarted PX4: the new connection replaces the old one
            self._connected()
        self._pace()
        self.lockstep_paced_wall_s += time.monotonic() - w0

    def _await(self, t_us: int) -> None:
        deadline = time.monotonic() + self.options.answer_timeout_s
        while self.answered_us < t_us and self.link.connected:
            left = deadline - time.monotonic()
            if left <= 0:
                self.counters["lockstep_timeouts"] += 1
                n = self.counters["lockstep_timeouts"]
                if n <= 3 or n % 100 == 0:
                    self.say(f"no HIL_ACTUATOR_CONTROLS for the step at t = {t_us * 1e-6:.3f} s within "
                             f"{self.options.answer_timeout_s:g} s (PX4 stalled or an answer was lost): stepping on "
                             f"with PX4's last outputs ({n} so far)")  # fmt: skip
                return
            for m in self.link.receive(left):
                self._on_px4(m)

    def _pace(self) -> None:
        speed = self.options.speed
        if speed <= 0:
            return
        ahead = (self.bridge.t - self._sim0) / speed - (time.monotonic() - self._wall0)
        if ahead > 0:
            time.sleep(ahead)
        elif -ahead * speed > MAX_LAG_S:
            self.counters["overruns"] += 1
            self._anchor()

    def _realtime_step(self) -> None:
        b = self.bridge
        now = time.monotonic()
        silent = now - self._last_answer_wall > self.options.realtime_timeout_s
        if self.state == Sync.REALTIME and silent and not self._frozen:
            self._frozen = True
            self.counters["freezes"] += 1
            self.say(f"no actuator outputs from PX4 for {self.options.realtime_timeout_s:g} s at t = {b.t:.2f} s: "
                     "the world is frozen until they come back")  # fmt: skip
        due = self._sim0 + (now - self._wall0)
        if not self._frozen and b.t <= due:
            self._send(b.step())
            if b.steps % SERVICE_STEPS == 0:
                self._service()
            wait = 0.0
        else:
            wait = min(b.imu_period_s, max(0.0, b.t - due)) if not self._frozen else 0.05
            self._service()
        for m in self.link.receive(wait):
            self._on_px4(m)
        if due - b.t > MAX_LAG_S:
            self.counters["overruns"] += 1
            self._anchor()

    # ------------------------------------------------------------------ input
    def _on_px4(self, m: Any) -> None:
        mtype = "HIL_ACTUATOR_CONTROLS" if type(m) is Controls else m.get_type()  # the one message of every step
        if mtype == "HIL_ACTUATOR_CONTROLS":
            self._learn_system(m.get_srcSystem())
            self.counters["answers"] += 1
            self.answered_us = max(self.answered_us, int(m.time_usec))
            self._last_answer_wall = time.monotonic()
            self.bridge.on_controls(m.controls, m.mode)
            lock = bool(int(m.flags) & FLAG_LOCKSTEP)
            if self.state == Sync.FREEWHEEL:
                self._engage(lock)
            elif self.state == Sync.LOCKSTEP and not lock:
                self.counters["answers_without_lockstep_flag"] += 1
            elif self._frozen:
                self._frozen = False
                self._anchor()
                self.say(f"actuator outputs from PX4 again: resuming at t = {self.bridge.t:.2f} s")
        elif mtype == "HEARTBEAT":
            if int(m.autopilot) != MAV_AUTOPILOT_INVALID:
                self._learn_system(m.get_srcSystem())
        elif mtype == "COMMAND_LONG":
            if int(m.command) == MAV_CMD_SET_MESSAGE_INTERVAL and int(m.param1) == MSG_ID_HIL_STATE_QUATERNION:
                self.bridge.set_state_rate(float(m.param2))
        else:
            self.counters["rx_ignored"] += 1
            self._received(m)  # HITL: what PX4 forwards arrives on this link

    def _engage(self, lock: bool) -> None:
        t = self.bridge.t
        self._anchor()
        if lock:
            self.state = Sync.LOCKSTEP
            self._cpu_mark = time.process_time()
            pace = "as fast as PX4 answers" if self.options.speed <= 0 else f"at speed {self.options.speed:g}"
            self.say(f"PX4 in lockstep from t = {t:.2f} s ({pace})")
            return
        self.state = Sync.REALTIME
        self._last_answer_wall = time.monotonic()
        ignored = "" if self.options.speed == 1.0 else " (the speed factor does not apply)"
        if isinstance(self.link, TcpSimLink):
            self.say("PX4 does not run in lockstep (HIL_ACTUATOR_CONTROLS flags bit 0 clear, a non-lockstep build): "
                     f"windseek steps in real time and applies its outputs as they come{ignored}")  # fmt: skip
        else:
            self.say(f"PX4 (HITL) answering from t = {t:.2f} s: stepping in real time{ignored}")

    def _learn_system(self, sysid: int) -> None:
        if sysid == self.px4_system or not 0 < sysid < 255:
            return
        self.px4_system = sysid
        self.link.encoder.srcSystem = sysid
        if self.peripheral is not None:
            self.peripheral.set_system_id(sysid)

    def _service(self) -> None:
        p = self.peripheral
        if p is None:
            return
        # A flight controller's USB port starts MAVLink only once it hears a HEARTBEAT (PX4's
        # cdcacm_autostart), so over serial the peripheral announces itself before PX4 has spoken
        # (as system 1, PX4's default, until PX4's id is known).
        if self.px4_system is not None or not isinstance(self.link, TcpSimLink):
            p.heartbeat(time.monotonic())
        for m in p.poll():
            self._received(m)

    def _received(self, m: Any) -> None:
        """A message the autopilot passed on: scored, then to the listeners."""
        self.bridge.truth.on_message(m)
        for hook in self.rx_hooks:
            hook(m)

    # ------------------------------------------------------------------ results
    def speed_line(self) -> str:
        """The lockstep pace in words: realised against requested, and the steps' throughput."""
        d = self.summary()
        if d["lockstep_speed"] is None:
            return "no lockstep"
        asked = "as fast as PX4 answers" if self.options.speed <= 0 else f"requested {self.options.speed:g}x"
        return (f"lockstep speed {d['lockstep_speed']:.2f}x ({asked}; the steps alone would allow "
                f"{d['lockstep_throughput']:.2f}x)")

    def summary(self) -> dict[str, Any]:
        """The bridge's figures, the sync state, the lockstep speeds and every counter.

        ``lockstep_speed``: simulated s per wall s the lockstep run went at (pacing included: about the
        requested ``speed`` when the steps keep up); ``lockstep_throughput``: the same over the steps' own
        time (world step + PX4's answer, no pacing sleep): how fast it could go (``--px4-free``);
        ``requested_speed``: the pace asked for (0: as fast as PX4 answers). None before any lockstep."""
        d = self.bridge.summary()
        d["sync"] = self.state.value
        d["px4_system_id"] = self.px4_system
        sim, paced, busy = self.lockstep_sim_s, self.lockstep_paced_wall_s, self.lockstep_wall_s
        d["lockstep_speed"] = round(sim / paced, 3) if paced else None
        d["lockstep_throughput"] = round(sim / busy, 3) if busy else None
        d["requested_speed"] = self.options.speed
        d["steps"] = self.bridge.steps
        n = max(1, round(self.lockstep_sim_s / self.bridge.imu_period_s))
        d["lockstep_us_per_step_windseek"] = round(1e6 * self.world_wall_s / n, 1)
        d["lockstep_us_per_step_px4"] = round(1e6 * self.px4_wall_s / n, 1)
        d["lockstep_cpu_us_per_step_windseek"] = round(1e6 * self.world_cpu_s / n, 1)
        for k in ("answers", "lockstep_timeouts", "disconnects", "reconnects", "freezes", "overruns"):
            d[k] = int(self.counters.get(k, 0))
        d.update({k: int(v) for k, v in self.counters.items()})
        d.update({f"link_{k}": int(v) for k, v in self.link.counters.items()})
        if self.peripheral is not None:
            d.update({f"peripheral_{k}": int(v) for k, v in self.peripheral.counters.items()})
        return d
