"""The loop that makes windseek ArduPilot's JSON physics: one reply per servo packet, in lockstep.

ArduPilot SITL (``--model JSON``) sends a servo packet to UDP 9002 for each of its physics frames
and waits for the state reply before it goes on; its clock is the replies' ``timestamp``. So the
world moves only when ArduPilot asks, and ArduPilot's ``--speedup`` sets the pace. Per packet,
by its ``frame_count`` (:mod:`sitl.ardupilot.json_protocol`):

- the next frame (or the first one seen): the outputs are checked and applied, the world advances
  one tick, the state goes back to the address the packet came from;
- the same frame again (ArduPilot resends after 1 s without a reply: ours was lost, or arrived
  late): the same reply again, the world does not move (``resends``);
- a lower frame count (ArduPilot restarted): said and counted (``restarts``); the world goes on
  (its time keeps running: ArduPilot's clock follows the timestamps), and if the restarted
  ArduPilot is disarmed while the vehicle is in the air, windseek's safety pilot lands it
  (:class:`sitl.hil.guard.ControlGuard`) rather than letting the stopped rotors drop it;
- a skipped frame count: counted (``frame_gaps``), then handled as the next frame.

A datagram that is not a servo packet (wrong size or magic) is dropped, counted and said once
per kind, and never answered. ArduPilot silent for ``stall_s`` wall seconds: said once (the world
is frozen, as lockstep implies) and said again when it resumes. Every wait is bounded.

Time: simulation time in s; ``wall`` names wall-clock seconds.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sitl.ardupilot.bridge import ArduPilotBridge
from sitl.ardupilot.json_protocol import PacketError, parse_servo_packet
from wire.dialect import mavlink

MAV_AUTOPILOT_INVALID = 8
#: Frames between two services of the peripheral link (10 = 12.5 ms of simulation time at 800 Hz).
SERVICE_FRAMES = 10
#: Rate asked of ArduPilot's WIND message on the peripheral's port [Hz of ArduPilot's clock].
WIND_HZ = 10.0
#: Wall seconds one wait for a servo packet lasts before the loop looks at its stop flag and the stall clock.
IDLE_S = 0.05


@dataclass
class JsonOptions:
    """host, port: where windseek listens for servo packets; stall_s: wall seconds of silence that
    are reported as a stall; spin_s: wall seconds to spin for the next packet when frames come back
    to back (0: never spin; :meth:`JsonRunner._next_datagram`)."""

    host: str = "127.0.0.1"
    port: int = 9002
    stall_s: float = 2.0
    spin_s: float = 0.0005


class JsonRunner:
    """The world (``bridge``), the UDP socket ArduPilot sends to, and the peripheral component
    (``peripheral``, or None) in one loop (module docstring); ``say`` gets one-line messages."""

    def __init__(self, bridge: ArduPilotBridge, options: JsonOptions, peripheral: Any,
                 say: Callable[[str], None]) -> None:  # fmt: skip
        self.bridge = bridge
        self.options = options
        self.peripheral = peripheral
        self.say = say
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((options.host, options.port))
        except OSError as e:
            self.sock.close()
            raise ValueError(f"cannot listen for ArduPilot on UDP {options.host}:{options.port}: {e.strerror}") from e
        self.port = int(self.sock.getsockname()[1])
        self.sock.setblocking(False)
        self.counters: Counter[str] = Counter()
        self.peer: tuple[str, int] | None = None
        self.last_count: int | None = None
        self.ardupilot_system: int | None = None
        self._stop = threading.Event()
        self._stalled = False
        self._said: set[str] = set()
        self._outbox: list[Any] = []
        #: callables(message) run for every message the peripheral passes on, after
        #: the truth scored it: listeners such as a recording.
        self.rx_hooks: list[Callable[[Any], None]] = []
        self._next_wind_ask = 0.0
        self.wall_first = self.wall_last = 0.0
        self.sim_first = 0.0
        self.cpu_s = 0.0  # CPU seconds of the process from the first frame on (spinning included)
        self.work_cpu_s = 0.0  # CPU seconds answering datagrams (spinning and idle waits excluded)
        self._cpu0 = 0.0

    def stop(self) -> None:
        """Ask the loop to return (thread-safe)."""
        self._stop.set()

    def serve(self, duration_s: float | None = None, wall_limit_s: float | None = None) -> None:
        """Answer servo packets until :meth:`stop`, ``duration_s`` of simulation time or ``wall_limit_s``."""
        b = self.bridge
        t_end = float("inf") if duration_s is None else b.t + duration_s
        wall_end = float("inf") if wall_limit_s is None else time.monotonic() + wall_limit_s
        last_rx = time.monotonic()
        while not self._stop.is_set() and b.t < t_end - 1e-9:
            got = self._next_datagram(last_rx)
            if got is None:
                now = time.monotonic()
                if now >= wall_end:
                    break
                if self.last_count is not None and not self._stalled and now - last_rx > self.options.stall_s:
                    self._on_stall()
                self._service()
                continue
            c0 = time.process_time()
            answered = self._on_datagram(*got)
            self.work_cpu_s += time.process_time() - c0
            if answered:
                last_rx = time.monotonic()
                if last_rx >= wall_end:
                    break
        self.cpu_s = time.process_time() - self._cpu0 if self.last_count is not None else 0.0

    def _next_datagram(self, last_rx: float) -> tuple[bytes, tuple[str, int]] | None:
        """The next datagram, or None after :data:`IDLE_S` without one. While frames come back to back,
        it spins on the socket for up to ``spin_s`` before it sleeps in ``select``: waking a sleeping
        process costs tens of microseconds on each of the two hand-offs of every frame, as much as the
        frame's work (ArduPilot SITL against a trivial responder on this machine: 5,400 frames/s
        sleeping, 10,000 spinning). Spinning only follows a frame that came quickly, so a paced or idle
        ArduPilot costs no CPU."""
        sock = self.sock
        if self.options.spin_s > 0 and time.monotonic() - last_rx < self.options.spin_s:
            end = time.monotonic() + self.options.spin_s
            while True:
                try:
                    return sock.recvfrom(4096)
                except BlockingIOError:
                    if time.monotonic() > end:
                        break
                except OSError:
                    break
        try:
            ready, _, _ = select.select([sock], [], [], IDLE_S)
            if ready:
                return sock.recvfrom(4096)
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self.counters["rx_errors"] += 1
            time.sleep(IDLE_S)  # bounded: an error that repeats does not spin
        return None

    def _on_stall(self) -> None:
        b = self.bridge
        self._stalled = True
        self.counters["stalls"] += 1
        w = b.world
        where = "on the ground" if w.on_ground else f"in the air at {-w.position[2]:.1f} m"
        self.say(f"no servo packet from ArduPilot for {self.options.stall_s:g} s at t = {b.t:.2f} s ({where}): "
                 "the world is frozen until it sends again")  # fmt: skip

    def _on_datagram(self, data: bytes, addr: tuple[str, int]) -> bool:
        try:
            pkt = parse_servo_packet(data)
        except PacketError as e:
            self.counters[f"rx_{e.kind}"] += 1
            self._say_once(e.kind, f"dropped a datagram from {addr[0]}:{addr[1]} that is not a servo packet: {e} "
                                   "(further ones counted)")  # fmt: skip
            return False
        b = self.bridge
        last = self.last_count
        if last is not None and pkt.frame_count == last:
            self.counters["resends"] += 1
            self._reply(b.repeat(), addr)
            return True
        self._classify(pkt.frame_count, last, addr)
        self.last_count = pkt.frame_count
        b.on_servos(pkt)
        out = b.step()
        self._reply(out.reply, addr)
        self.counters["frames"] += 1
        if self.ardupilot_system is not None:
            self._outbox.extend(out.to_companion)
        if self.counters["frames"] % SERVICE_FRAMES == 0:
            self._service()
        return True

    def _classify(self, count: int, last: int | None, addr: tuple[str, int]) -> None:
        b = self.bridge
        if last is None:
            self.say(f"ArduPilot connected from {addr[0]}:{addr[1]} (frame {count}) at t = {b.t:.2f} s: in lockstep")
            self.wall_first = time.monotonic()
            self.sim_first = b.t
            self._cpu0 = time.process_time()
        elif count < last:
            self.counters["restarts"] += 1
            self.say(f"ArduPilot restarted (frame {count} after {last}, from {addr[0]}:{addr[1]}) at t = {b.t:.2f} s: "
                     "the world goes on")  # fmt: skip
            b.guard.on_reconnect()
        elif count > last + 1:
            self.counters["frame_gaps"] += 1
        if self._stalled:
            self._stalled = False
            self.say(f"servo packets from ArduPilot again: resuming at t = {b.t:.2f} s")
        self.peer = addr

    def _reply(self, reply: bytes, addr: tuple[str, int]) -> None:
        try:
            self.sock.sendto(reply, addr)
            self.wall_last = time.monotonic()
        except OSError:
            self.counters["tx_errors"] += 1

    def _say_once(self, kind: str, text: str) -> None:
        if kind not in self._said:
            self._said.add(kind)
            self.say(text)

    def _service(self) -> None:
        p = self.peripheral
        if p is None:
            return
        if self._outbox:
            p.send(self._outbox)
            self._outbox = []
        for m in p.poll():
            if m.get_type() == "HEARTBEAT" and int(m.autopilot) != MAV_AUTOPILOT_INVALID:
                self._learn_system(m.get_srcSystem())
            self.bridge.truth.on_message(m)
            for hook in self.rx_hooks:
                hook(m)
        if self.ardupilot_system is not None:
            now = time.monotonic()
            p.heartbeat(now)
            if not self.bridge.truth.autopilot.received and now >= self._next_wind_ask:
                # ArduPilot's own wind estimate (EKF3's WIND), scored apart from the companions' (one ask every
                # 5 s until it streams: ArduPilot streams on a port only what was asked for there).
                self._next_wind_ask = now + 5.0
                p.send([mavlink.MAVLink_command_long_message(self.ardupilot_system, 1,
                                                             mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                             float(mavlink.MAVLINK_MSG_ID_WIND), 1e6 / WIND_HZ,
                                                             0, 0, 0, 0, 0)])  # fmt: skip

    def _learn_system(self, sysid: int) -> None:
        if sysid != self.ardupilot_system and 0 < sysid < 255:
            self.ardupilot_system = sysid
            if self.peripheral is not None:
                self.peripheral.set_system_id(sysid)

    def close(self) -> None:
        self.sock.close()
        if self.peripheral is not None:
            self.peripheral.close()

    def summary(self) -> dict[str, Any]:
        """The bridge's figures, the lockstep speed and every counter."""
        d = self.bridge.summary()
        wall = self.wall_last - self.wall_first
        sim = self.bridge.t - self.sim_first
        d["ardupilot_system_id"] = self.ardupilot_system
        d["lockstep_speed"] = round(sim / wall, 3) if self.last_count is not None and wall > 0 else None
        n = max(1, self.counters.get("frames", 0))
        d["cpu_us_per_frame_windseek"] = round(1e6 * self.work_cpu_s / n, 1)
        d["cpu_us_per_frame_windseek_with_spin"] = round(1e6 * self.cpu_s / n, 1)
        for k in ("frames", "resends", "restarts", "frame_gaps", "stalls"):
            d[k] = int(self.counters.get(k, 0))
        d.update({k: int(v) for k, v in self.counters.items()})
        if self.peripheral is not None:
            d.update({f"peripheral_{k}": int(v) for k, v in self.peripheral.counters.items()})
        return d
