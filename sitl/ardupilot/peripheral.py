"""windseek's sensors as a MAVLink component of an ArduPilot vehicle: a TCP client of one of its serial ports.

The same component as with PX4 (:mod:`sitl.hil.peripheral`: system = the autopilot's, component
158, ESC_STATUS, NAMED_VALUE_FLOAT ``CHEM`` and ``TRUEWN/TRUEWE/TRUEWD``, a 1 Hz HEARTBEAT as
``MAV_TYPE_GENERIC`` / ``MAV_AUTOPILOT_INVALID``). ArduPilot SITL serves its serial ports as TCP
servers (``SERIAL0`` 5760, ``SERIAL1`` 5762, ``SERIAL2`` 5763, plus 10 per instance ``-I N``), all
MAVLink 2. windseek connects to ``SERIAL2`` by default, leaving 5760 to the ground station and
5762 to the companion programs. ArduPilot's MAVLink routing (``GCS_MAVLink/MAVLink_routing.cpp``)
forwards a message without a target to every other MAVLink channel, so what windseek publishes
reaches the ground station and the companions, and what they publish (the estimator's WIND_COV,
the mission's declaration) comes back here to be scored (:mod:`sitl.hil.summary`).

Every wait is bounded: the connection is retried once per ``retry_s`` wall seconds without
blocking, a send that would block is dropped and counted (``tx_dropped``), a read takes what is
there.
"""

from __future__ import annotations

import contextlib
import errno
import socket
import time
from collections import Counter
from typing import Any

from sitl.hil.frames import FrameEncoder
from sitl.hil.messages import heartbeat_peripheral
from sitl.hil.peripheral import PERIPHERAL_COMPONENT, parse_frames
from wire.dialect import mavlink

#: ArduPilot SITL's SERIAL2 TCP port of instance 0; instance N adds 10 * N.
ARDUPILOT_SERIAL2_PORT = 5763


class TcpPeripheral:
    """The peripheral component on a TCP connection to ArduPilot's serial port at ``target`` (host, port)."""

    def __init__(self, target: tuple[str, int], system_id: int = 1, retry_s: float = 1.0) -> None:
        self.target = (target[0], int(target[1]))
        self.retry_s = float(retry_s)
        self.encoder = FrameEncoder(system_id, PERIPHERAL_COMPONENT)
        self._parser = mavlink.MAVLink(None, 0, 0)
        self._parser.robust_parsing = True
        self.counters: Counter[str] = Counter()
        self.name = f"tcp:{self.target[0]}:{self.target[1]}"
        self.sock: socket.socket | None = None
        self._connecting = False
        self._next_try = 0.0
        self._last_hb = -1e9

    @property
    def system_id(self) -> int:
        return int(self.encoder.srcSystem)

    def set_system_id(self, system_id: int) -> None:
        self.encoder.srcSystem = int(system_id)

    @property
    def connected(self) -> bool:
        return self.sock is not None and not self._connecting

    def _connect(self) -> None:
        now = time.monotonic()
        if self.sock is not None or now < self._next_try:
            return
        self._next_try = now + self.retry_s
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setblocking(False)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        err = s.connect_ex(self.target)
        if err not in (0, errno.EINPROGRESS):
            s.close()
            return
        self.sock, self._connecting = s, err != 0

    def _check_connected(self) -> bool:
        s = self.sock
        if s is None:
            return False
        if self._connecting:
            err = s.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err == errno.EINPROGRESS or err == errno.EALREADY:
                return False
            if err != 0:
                self._drop()
                return False
            try:
                s.getpeername()
            except OSError:
                return False  # still connecting
            self._connecting = False
            self.counters["connects"] += 1
        return True

    def _drop(self) -> None:
        if self.sock is not None:
            with contextlib.suppress(OSError):
                self.sock.close()
        if self.sock is not None and not self._connecting:
            self.counters["disconnects"] += 1
        self.sock, self._connecting = None, False

    def send(self, msgs: list[Any]) -> None:
        """The messages as one write; dropped and counted while not connected or when it would block."""
        if not msgs:
            return
        self._connect()
        if not self._check_connected():
            self.counters["tx_dropped"] += len(msgs)
            return
        data = b"".join(self.encoder.encode(m) for m in msgs)
        try:
            n = self.sock.send(data)  # type: ignore[union-attr]
        except BlockingIOError:
            n = 0
        except OSError:
            self._drop()
            self.counters["tx_dropped"] += len(msgs)
            return
        if n < len(data):
            # A partial frame would corrupt the stream: the connection is reset (ArduPilot drops the rest).
            self.counters["tx_dropped"] += len(msgs)
            if n > 0:
                self._drop()
            return
        self.counters["tx_messages"] += len(msgs)

    def heartbeat(self, now_wall_s: float) -> None:
        if now_wall_s - self._last_hb >= 1.0:
            self._last_hb = now_wall_s
            self.send([heartbeat_peripheral()])

    def poll(self) -> list[Any]:
        """Messages ArduPilot sent on this port (its streams and what it forwards); never blocks."""
        self._connect()
        if not self._check_connected():
            return []
        out: list[Any] = []
        for _ in range(16):  # bounded: at most 16 reads per call
            try:
                data = self.sock.recv(65536)  # type: ignore[union-attr]
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._drop()
                break
            if not data:
                self._drop()
                break
            out.extend(parse_frames(self._parser, data, self.counters))
        self.counters["rx_messages"] += len(out)
        return out

    def close(self) -> None:
        self._drop()
