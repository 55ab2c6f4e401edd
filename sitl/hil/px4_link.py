"""The byte link to PX4's simulator side: a TCP server PX4 SITL connects to, or a serial port (HITL).

PX4 SITL's ``simulator_mavlink`` is a TCP client: it connects to the simulator on port 4560 +
instance and retries until the simulator listens (PX4 ``SimulatorMavlink.cpp:1153-1184``).
:class:`TcpSimLink` listens and keeps **one** PX4: a new connection replaces the old one (PX4
restarted). :class:`SerialSimLink` is a serial device (a flight controller with ``SYS_HITL 1`` on
USB or a telemetry port, or a pseudo-terminal in the tests), always "connected" unless the device
hangs up.

Both parse with the project dialect (:mod:`wire.dialect`), one parser per connection; frames that
do not parse are counted (``rx_bad``) and dropped. Writes are bounded: a TCP peer that reads
nothing for ``send_timeout_s`` is dropped (counted), a serial write that does not fit is counted
(``tx_short``). Every wait has a timeout.
"""

from __future__ import annotations

import contextlib
import select
import socket
import struct
import time
from collections import Counter
from typing import Any

from sitl.hil.frames import FrameEncoder, split_controls
from sitl.link.transports import SerialTransport
from wire.resync import ResyncMAVLink

#: Wall seconds a TCP send may block on a peer that does not read.
SEND_TIMEOUT_S = 2.0
#: Wall seconds one blocking TCP read waits at most (the kernel's receive timeout): a wait at least this
#: long is one read, and its caller tries again until its own deadline.
RECV_SLICE_S = 0.05


def _timeval(seconds: float) -> bytes:
    """A ``struct timeval`` for SO_SNDTIMEO / SO_RCVTIMEO."""
    sec = int(seconds)
    return struct.pack("ll", sec, int(round((seconds - sec) * 1e6)))


class SimLink:
    """Base: a MAVLink byte link to PX4 (see the module docstring)."""

    name = "px4"

    def __init__(self, system_id: int, component_id: int) -> None:
        self.counters: Counter[str] = Counter()
        self.encoder = FrameEncoder(system_id, component_id)
        self._parser = self._new_parser()
        #: Frames sent and received, for a .tlog (``(frame, sent)``); None = not kept.
        self.tap: Any = None

    def _new_parser(self) -> Any:
        return ResyncMAVLink(None, 0, 0)  # re-scans the bytes of a corrupt frame (wire.resync)

    @property
    def connected(self) -> bool:
        raise NotImplementedError

    def fileno(self) -> int | None:
        """The descriptor to poll for input (None while not connected)."""
        raise NotImplementedError

    def accept(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for PX4 to connect; True if a (new) connection was made."""
        raise NotImplementedError

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _read(self) -> bytes:
        raise NotImplementedError

    def encode(self, msgs: list[Any]) -> list[bytes]:
        """One frame per message, with our identity and sequence numbers."""
        enc = self.encoder.encode
        return [enc(m) for m in msgs]

    def send(self, msgs: list[Any]) -> None:
        """Send messages in one write (no-op while not connected)."""
        if not msgs or not self.connected:
            return
        frames = self.encode(msgs)
        if self.tap is not None:
            for f in frames:
                self.tap(f, True)
        self._write(b"".join(frames))
        self.counters["tx_messages"] += len(msgs)

    def _wait_read(self, timeout_s: float) -> bytes:
        """The bytes that arrive within ``timeout_s`` (b"" on timeout)."""
        fd = self.fileno()
        if fd is None:
            return b""
        try:
            ready, _, _ = select.select([fd], [], [], max(0.0, timeout_s))
        except (InterruptedError, ValueError, OSError):
            return b""
        return self._read() if ready else b""

    def receive(self, timeout_s: float) -> list[Any]:
        """Messages that arrive within ``timeout_s`` (returns at the first batch; [] on timeout)."""
        data = self._wait_read(timeout_s)
        if not data:
            return []
        self.counters["rx_bytes"] += len(data)
        good: list[Any] = []
        if self._parser.buf_len() == 0:  # at a frame boundary: PX4's answers decoded without the generic parser
            good, data = split_controls(data)
            if self.tap is not None:
                for m in good:
                    self.tap(m.get_msgbuf(), False)
            if not data:
                self.counters["rx_messages"] += len(good)
                return good
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - the parser must never take the link down
            self.counters["rx_bad"] += 1
            self._parser = self._new_parser()
            return good
        for m in msgs:
            mtype = m.get_type()
            if mtype == "BAD_DATA" or mtype.startswith("UNKNOWN_"):
                self.counters["rx_bad"] += 1
                continue
            if self.tap is not None:
                self.tap(m.get_msgbuf(), False)
            good.append(m)
        self.counters["rx_messages"] += len(good)
        return good

    def close(self) -> None:
        raise NotImplementedError


class TcpSimLink(SimLink):
    """A TCP server on ``(host, port)`` holding one PX4 connection."""

    def __init__(self, host: str, port: int, system_id: int, component_id: int) -> None:
        super().__init__(system_id, component_id)
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind((host, port))
        self.server.listen(2)
        self.server.setblocking(False)
        self.conn: socket.socket | None = None
        self.peer: tuple[str, int] | None = None
        self.name = f"tcp:{host}:{self.port}"

    @property
    def port(self) -> int:
        return int(self.server.getsockname()[1])

    @property
    def connected(self) -> bool:
        return self.conn is not None

    def fileno(self) -> int | None:
        return None if self.conn is None else self.conn.fileno()

    def accept(self, timeout_s: float) -> bool:
        try:
            ready, _, _ = select.select([self.server], [], [], max(0.0, timeout_s))
        except (InterruptedError, ValueError, OSError):
            return False
        if not ready:
            return False
        try:
            conn, addr = self.server.accept()
        except OSError:
            return False
        if self.conn is not None:
            self.counters["replaced"] += 1
            self.drop()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        # A blocking socket with the kernel's timeouts, not Python's settimeout: with a Python timeout every send
        # and recv polls the socket first (two more system calls per lockstep step).
        conn.setblocking(True)
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, _timeval(SEND_TIMEOUT_S))
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, _timeval(RECV_SLICE_S))
        self.conn, self.peer = conn, addr
        self._parser = self._new_parser()
        self.counters["connections"] += 1
        return True

    def pending(self) -> bool:
        """True if another PX4 is waiting to connect (a restarted PX4 while the old socket is open)."""
        try:
            ready, _, _ = select.select([self.server], [], [], 0.0)
        except (InterruptedError, ValueError, OSError):
            return False
        return bool(ready)

    def _write(self, data: bytes) -> None:
        assert self.conn is not None
        try:
            self.conn.sendall(data)
        except OSError:  # the send timeout (EAGAIN), a reset or a closed peer
            self.counters["tx_dropped_peer"] += 1
            self.drop()

    def _wait_read(self, timeout_s: float) -> bytes:
        # The lockstep wait: one blocking recv (the kernel's RECV_SLICE_S timeout) instead of select + recv;
        # shorter waits (real-time steps) take the select path.
        if self.conn is None or timeout_s < RECV_SLICE_S:
            return super()._wait_read(timeout_s)
        return self._read()

    def _read(self) -> bytes:
        if self.conn is None:
            return b""
        try:
            data = self.conn.recv(65536)
        except (BlockingIOError, InterruptedError, TimeoutError):
            return b""
        except OSError:
            data = b""
        if not data:
            self.drop()
        return data

    def drop(self) -> None:
        """Close the current PX4 connection (it closed, or stopped reading)."""
        if self.conn is not None:
            with contextlib.suppress(OSError):
                self.conn.close()
            self.conn = None
            self.counters["disconnects"] += 1

    def close(self) -> None:
        if self.conn is not None:
            with contextlib.suppress(OSError):
                self.conn.close()
            self.conn = None
        self.server.close()


class SerialSimLink(SimLink):
    """A serial device at ``baud`` (8N1, raw), e.g. a flight controller's USB port with ``SYS_HITL 1``."""

    def __init__(self, device: str, baud: int, system_id: int, component_id: int) -> None:
        super().__init__(system_id, component_id)
        self.transport = SerialTransport(device, baud)
        self.baud = baud
        self.name = f"serial:{device}:{baud}"
        self._opened = time.monotonic()

    @property
    def connected(self) -> bool:
        return not self.transport.hung_up

    def fileno(self) -> int | None:
        fds = self.transport.fds()
        return fds[0] if fds else None

    def accept(self, timeout_s: float) -> bool:
        time.sleep(max(0.0, min(timeout_s, 0.1)))  # a hung-up device does not come back on its own
        return False

    def _write(self, data: bytes) -> None:
        before = self.transport.stats.tx_errors
        self.transport.write(data)
        if self.transport.stats.tx_errors > before:
            self.counters["tx_short"] += 1

    def _read(self) -> bytes:
        return self.transport.read(self.transport.fd)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.transport.close()
