"""Byte pipes of the MAVLink endpoint: UDP, TCP server and serial, all non-blocking.

A transport knows nothing about MAVLink: the endpoint polls :meth:`Transport.fds`, calls
:meth:`Transport.read` when one is readable and :meth:`Transport.write` to send. A transport
may carry several peers (UDP peers, TCP clients); a write goes to all of them, because
MAVLink is a broadcast protocol and every ground station and API expects every stream.
"""

from __future__ import annotations

import errno
import os
import socket
import termios
import time
import tty
from dataclasses import dataclass

#: Largest datagram we read; a MAVLink 2 frame is at most 280 bytes, a UDP packet may hold several.
_MAX_READ = 65536


def parse_host_port(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """``HOST:PORT`` or ``PORT`` to (host, port); ValueError with the accepted forms otherwise."""
    host, _, port = text.rpartition(":")
    try:
        p = int(port)
    except ValueError:
        raise ValueError(f"{text!r}: expected HOST:PORT or PORT (e.g. 127.0.0.1:14540)") from None
    if not 0 <= p <= 65535:
        raise ValueError(f"{text!r}: port must be in [0, 65535]")
    return (host or default_host), p


@dataclass
class TransportStats:
    rx_bytes: int = 0
    tx_bytes: int = 0
    tx_errors: int = 0
    peers_learned: int = 0
    peers_expired: int = 0
    peers_evicted: int = 0


class Transport:
    """Base class: a named, non-blocking byte pipe to one or more peers."""

    name = "transport"

    def __init__(self) -> None:
        self.stats = TransportStats()

    def fds(self) -> list[int]:
        """File descriptors to poll for reading."""
        raise NotImplementedError

    def read(self, fd: int) -> bytes:
        """Bytes available on ``fd`` (readable per select); b"" if none."""
        raise NotImplementedError

    def write(self, data: bytes) -> None:
        """Send to every peer; never blocks (a full buffer drops the frame and counts it)."""
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


class UdpTransport(Transport):
    """One UDP socket bound to ``bind`` that sends to ``peers`` and to whoever talks to it.

    Like PX4's ``mavlink start -u ... -o ...``: the configured peers (an API port, a ground
    station port) get every message before they ever talk and stay for good. A sender from another
    address is *learned* by the endpoint (:meth:`learn`) once one of its datagrams held a valid frame
    (an authenticated one when signing is on), and is then sent everything too. Learned peers are
    bounded (``MAX_LEARNED``: a new one evicts the longest silent) and expire after ``PEER_TIMEOUT_S``
    wall seconds of silence; both are counted in :attr:`stats`.
    """

    MAX_LEARNED = 32
    PEER_TIMEOUT_S = 30.0

    def __init__(self, peers: list[tuple[str, int]], bind: tuple[str, int] = ("0.0.0.0", 0)) -> None:
        super().__init__()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(bind)
        self.sock.setblocking(False)
        self.configured: list[tuple[str, int]] = [(socket.gethostbyname(h), p) for h, p in peers]
        self.learned: dict[tuple[str, int], float] = {}  # address -> last time heard (monotonic s)
        self._next_expiry = 0.0
        self.name = f"udp:{self.port}"

    @property
    def peers(self) -> list[tuple[str, int]]:
        """Everyone a broadcast goes to: the configured peers, then the learned ones."""
        return self.configured + [a for a in self.learned if a not in self.configured]

    def learn(self, addr: tuple[str, int], now: float | None = None) -> None:
        """A sender proved to speak MAVLink (to us): answer it from now on (bounded, expiring)."""
        now = time.monotonic() if now is None else now
        if addr in self.configured:
            return
        if addr not in self.learned:
            if len(self.learned) >= self.MAX_LEARNED:
                oldest = min(self.learned, key=self.learned.__getitem__)
                del self.learned[oldest]
                self.stats.peers_evicted += 1
            self.stats.peers_learned += 1
        self.learned[addr] = now

    def expire(self, now: float | None = None) -> None:
        """Forget learned peers silent for ``PEER_TIMEOUT_S`` (checked at most once a second)."""
        now = time.monotonic() if now is None else now
        if now < self._next_expiry:
            return
        self._next_expiry = now + 1.0
        for addr in [a for a, t in self.learned.items() if now - t > self.PEER_TIMEOUT_S]:
            del self.learned[addr]
            self.stats.peers_expired += 1

    @property
    def port(self) -> int:
        """The local port (useful when bound to port 0)."""
        return self.sock.getsockname()[1]

    def fds(self) -> list[int]:
        return [self.sock.fileno()]

    def read(self, fd: int) -> list[bytes]:  # type: ignore[override]
        # One entry per datagram: a MAVLink frame never spans datagrams, so the endpoint parses
        # each on its own and a truncated frame cannot swallow the next sender's frame.
        chunks: list[bytes] = []  # Datagrams
        while True:
            try:
                data, addr = self.sock.recvfrom(_MAX_READ)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                # ICMP port unreachable from a peer not (yet) listening surfaces here on Linux.
                continue
            chunks.append(Datagram(data, addr))
            self.stats.rx_bytes += len(data)
        return chunks

    def write(self, data: bytes) -> None:
        self.write_except(data, None)

    def write_except(self, data: bytes, skip: tuple[str, int] | None) -> None:
        """Send to every peer but ``skip`` (the sender of a forwarded frame)."""
        self.expire()
        for peer in self.peers:
            if peer == skip:
                continue
            try:
                self.sock.sendto(data, peer)
                self.stats.tx_bytes += len(data)
            except OSError:
                self.stats.tx_errors += 1

    def send_to(self, data: bytes, peer: tuple[str, int]) -> None:
        """Send to one peer only (an answer to the peer that asked)."""
        try:
            self.sock.sendto(data, peer)
            self.stats.tx_bytes += len(data)
        except OSError:
            self.stats.tx_errors += 1

    def close(self) -> None:
        self.sock.close()


class Datagram(bytes):
    """A received UDP datagram that remembers its sender (``addr``), for message forwarding."""

    addr: tuple[str, int] | None

    def __new__(cls, data: bytes, addr: tuple[str, int] | None = None) -> Datagram:
        obj = super().__new__(cls, data)
        obj.addr = addr
        return obj


class TcpServerTransport(Transport):
    """A TCP server; every connected client is a peer. Clients may come and go."""

    def __init__(self, port: int, host: str = "0.0.0.0") -> None:
        super().__init__()
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind((host, port))
        self.server.listen(8)
        self.server.setblocking(False)
        self.clients: dict[int, socket.socket] = {}
        self.name = f"tcp:{self.port}"

    @property
    def port(self) -> int:
        return self.server.getsockname()[1]

    def fds(self) -> list[int]:
        return [self.server.fileno(), *self.clients]

    def read(self, fd: int) -> bytes:
        conn: socket.socket | None
        if fd == self.server.fileno():
            try:
                conn, _ = self.server.accept()
            except OSError:
                return b""
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.clients[conn.fileno()] = conn
            return b""
        conn = self.clients.get(fd)
        if conn is None:
            return b""
        try:
            data = conn.recv(_MAX_READ)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            data = b""
        if not data:
            self._drop(fd)
            return b""
        self.stats.rx_bytes += len(data)
        return data

    def send_to(self, data: bytes, fd: int) -> None:
        """Send to one client only (an answer to the client that asked); gone clients are skipped."""
        conn = self.clients.get(fd)
        if conn is None:
            return
        try:
            n = conn.send(data)
            self.stats.tx_bytes += n
            if n < len(data):
                # A partial frame would desynchronise the peer's parser for one frame only;
                # MAVLink resynchronises on the next start byte, so count it and move on.
                self.stats.tx_errors += 1
        except (BlockingIOError, InterruptedError):
            self.stats.tx_errors += 1
        except OSError:
            self._drop(fd)

    def _drop(self, fd: int) -> None:
        conn = self.clients.pop(fd, None)
        if conn is not None:
            conn.close()

    def write(self, data: bytes) -> None:
        for fd in list(self.clients):
            self.send_to(data, fd)

    def close(self) -> None:
        for fd in list(self.clients):
            self._drop(fd)
        self.server.close()


_BAUDS = {b: getattr(termios, f"B{b}") for b in (9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)
          if hasattr(termios, f"B{b}")}  # fmt: skip


class SerialTransport(Transport):
    """A serial device (or pseudo-terminal) in raw mode, 8N1 at ``baud``."""

    def __init__(self, device: str, baud: int = 57600) -> None:
        super().__init__()
        if baud not in _BAUDS:
            raise ValueError(f"baud {baud}: allowed values are {', '.join(map(str, _BAUDS))}")
        self.device = device
        self.fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)
        attrs = termios.tcgetattr(self.fd)
        attrs[4] = attrs[5] = _BAUDS[baud]
        termios.tcsetattr(self.fd, termios.TCSANOW, attrs)
        self.name = f"serial:{device}"
        self.hung_up = False

    def fds(self) -> list[int]:
        # After a hang-up the fd stays "readable" forever (EIO): stop polling it instead of spinning.
        return [] if self.hung_up else [self.fd]

    def read(self, fd: int) -> bytes:
        try:
            data = os.read(self.fd, _MAX_READ)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError as e:
            if e.errno == errno.EIO:  # the device went away (the other end of a pty closed)
                self.hung_up = True
                return b""
            raise
        self.stats.rx_bytes += len(data)
        return data

    def write(self, data: bytes) -> None:
        try:
            n = os.write(self.fd, data)
            self.stats.tx_bytes += n
            if n < len(data):
                self.stats.tx_errors += 1
        except (BlockingIOError, InterruptedError, OSError):
            self.stats.tx_errors += 1

    def close(self) -> None:
        os.close(self.fd)


def parse_serial(text: str) -> tuple[str, int]:
    """``DEV[:BAUD]`` to (device, baud), baud 57600 by default. A device path may itself hold colons
    (``/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0``): the text after the last colon is a
    baud rate only when it is a number, or when the part before it names an existing device.
    ValueError (one line) on a bad baud rate."""
    dev, sep, baud = text.rpartition(":")
    if sep and baud.isdigit():
        rate = int(baud)
    elif sep and baud and os.path.exists(dev) and not os.path.exists(text):
        raise ValueError(f"serial {text!r}: baud rate {baud!r} is not a number; allowed values are "
                         f"{', '.join(map(str, _BAUDS))}")  # fmt: skip
    else:
        dev, rate = text, 57600
    if rate not in _BAUDS:
        raise ValueError(f"serial {text!r}: baud rate {rate}: allowed values are {', '.join(map(str, _BAUDS))}")
    return dev, rate
