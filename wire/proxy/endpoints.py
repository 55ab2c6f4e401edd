"""The link proxy's two ends: UDP (listen or send first) and TCP (listen or connect), non-blocking.

An endpoint turns what arrives into *units* for the fault model and sends units back out:

- UDP: one datagram is one unit (what a network loses is a datagram, and PX4 and ``windseek sitl``
  pack several frames into one), or with ``frames=True`` one MAVLink frame is one unit (a
  telemetry radio loses frames), each sent as its own datagram;
- TCP: a byte stream has no packets, so it is cut into MAVLink frames (:mod:`wire.proxy.framing`).

Specs: ``udpin:HOST:PORT`` (also ``udp:``, ``udpin://``, ``udp://``) listens and answers whoever sent
last (up to :data:`MAX_PEERS` senders); ``udpout:HOST:PORT`` sends to that address from an
ephemeral port; ``tcpin:HOST:PORT`` accepts up to :data:`MAX_PEERS` clients; ``tcpout:HOST:PORT``
(also ``tcp:``) connects, and reconnects every :data:`RECONNECT_S` after a failure. Port 0 on a
listening end binds a free port (see :attr:`Endpoint.port`). Every buffer is bounded and every drop
counted in :attr:`Endpoint.counters`.
"""

from __future__ import annotations

import errno
import math
import socket
from collections import Counter
from dataclasses import dataclass

from wire.proxy.framing import FrameSplitter, split_datagram

MAX_PEERS = 8
RECONNECT_S = 1.0
#: Bytes waiting to be written to one TCP peer at most (beyond: the unit is dropped and counted).
TCP_OUTBOX = 65536
#: Datagrams read from one socket per call at most (the other end gets its turn).
READ_BURST = 256
_KINDS = {"udpin": "udpin", "udp": "udpin", "udpout": "udpout", "tcpin": "tcpin", "tcpout": "tcpout",
          "tcp": "tcpout"}  # fmt: skip


@dataclass(frozen=True)
class EndpointSpec:
    kind: str  # udpin, udpout, tcpin, tcpout
    host: str
    port: int

    @staticmethod
    def parse(text: str) -> EndpointSpec:
        """``KIND:HOST:PORT`` or ``KIND://HOST:PORT``; ValueError (one line) otherwise."""
        kind, sep, rest = text.partition(":")
        rest = rest[2:] if rest.startswith("//") else rest
        host, _, port = rest.rpartition(":")
        ok = sep and kind in _KINDS and port.isdigit() and int(port) <= 65535 and host
        if not ok:
            raise ValueError(f"endpoint {text!r}: expected udpin:HOST:PORT, udpout:HOST:PORT, tcpin:HOST:PORT or "
                             "tcpout:HOST:PORT (or the MAVSDK form udpin://HOST:PORT)")  # fmt: skip
        spec = EndpointSpec(_KINDS[kind], host, int(port))
        if spec.kind in ("udpout", "tcpout") and spec.port == 0:
            raise ValueError(f"endpoint {text!r}: a {spec.kind} end needs the peer's port (not 0)")
        return spec

    def __str__(self) -> str:
        return f"{self.kind}:{self.host}:{self.port}"


class Endpoint:
    """Base: see the module docstring."""

    def __init__(self, spec: EndpointSpec) -> None:
        self.spec = spec
        self.counters: Counter[str] = Counter()

    @property
    def port(self) -> int:
        """The local port of a listening end (the peer's port otherwise)."""
        return self.spec.port

    def describe(self) -> str:
        return f"{self.spec.kind}:{self.spec.host}:{self.port}"

    def rfds(self) -> list[int]:
        raise NotImplementedError

    def wfds(self) -> list[int]:
        return []

    def read(self, fd: int) -> list[bytes]:
        raise NotImplementedError

    def writable(self, fd: int) -> None:
        """``fd`` (one of :meth:`wfds`) can be written."""

    def send(self, unit: bytes) -> bool:
        """Send to every peer; False when there was none (nothing sent)."""
        raise NotImplementedError

    def tick(self, now: float) -> None:
        """Periodic work (reconnects); ``now`` in monotonic seconds."""

    def close(self) -> None:
        raise NotImplementedError


class UdpEndpoint(Endpoint):
    def __init__(self, spec: EndpointSpec, frames: bool = False) -> None:
        super().__init__(spec)
        self.frames = frames
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.peers: list[tuple[str, int]] = []
        if spec.kind == "udpin":
            self.sock.bind((spec.host, spec.port))
        else:
            self.sock.bind(("0.0.0.0", 0))
            self.peers.append((socket.gethostbyname(spec.host), spec.port))
        self._splitter = FrameSplitter()

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1]) if self.spec.kind == "udpin" else self.spec.port

    def rfds(self) -> list[int]:
        return [self.sock.fileno()]

    def read(self, fd: int) -> list[bytes]:
        out: list[bytes] = []
        for _ in range(READ_BURST):
            try:
                data, addr = self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # ICMP port unreachable from a peer that is not listening (yet)
                self.counters["rx_errors"] += 1
                continue
            if self.spec.kind == "udpin" and (not self.peers or self.peers[-1] != addr):
                if addr in self.peers:
                    self.peers.remove(addr)
                self.peers.append(addr)
                del self.peers[:-MAX_PEERS]
            if self.frames:
                frames, bad = split_datagram(data, self._splitter)
                self.counters["garbage_bytes"] += bad
                out.extend(frames)
            else:
                out.append(data)
        return out

    def send(self, unit: bytes) -> bool:
        for peer in self.peers:
            try:
                self.sock.sendto(unit, peer)
            except OSError:  # a full buffer, a peer that went away: the unit is lost, as on a network
                self.counters["send_errors"] += 1
        return bool(self.peers)

    def close(self) -> None:
        self.sock.close()


class _TcpPeer:
    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.splitter = FrameSplitter()
        self.outbox = bytearray()


class TcpEndpoint(Endpoint):
    def __init__(self, spec: EndpointSpec) -> None:
        super().__init__(spec)
        self.peers: dict[int, _TcpPeer] = {}
        self.server: socket.socket | None = None
        self._connecting: socket.socket | None = None
        self._retry_at = -math.inf
        if spec.kind == "tcpin":
            self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.server.bind((spec.host, spec.port))
            self.server.listen(MAX_PEERS)
            self.server.setblocking(False)

    @property
    def port(self) -> int:
        return int(self.server.getsockname()[1]) if self.server is not None else self.spec.port

    def rfds(self) -> list[int]:
        return ([self.server.fileno()] if self.server is not None else []) + list(self.peers)

    def wfds(self) -> list[int]:
        fds = [fd for fd, p in self.peers.items() if p.outbox]
        return fds + ([self._connecting.fileno()] if self._connecting is not None else [])

    def tick(self, now: float) -> None:
        if self.spec.kind != "tcpout" or self.peers or self._connecting is not None or now < self._retry_at:
            return
        self._retry_at = now + RECONNECT_S
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setblocking(False)
        err = s.connect_ex((self.spec.host, self.spec.port))
        if err not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
            self.counters["connect_errors"] += 1
            s.close()
            return
        self._connecting = s

    def writable(self, fd: int) -> None:
        s = self._connecting
        if s is not None and fd == s.fileno():
            self._connecting = None
            if s.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) != 0:
                self.counters["connect_errors"] += 1
                s.close()
                return
            self._add(s)
            return
        peer = self.peers.get(fd)
        if peer is not None:
            self._flush(fd, peer)

    def _add(self, s: socket.socket) -> None:
        s.setblocking(False)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.peers[s.fileno()] = _TcpPeer(s)
        self.counters["connects"] += 1

    def _drop(self, fd: int) -> None:
        peer = self.peers.pop(fd, None)
        if peer is not None:
            self.counters["garbage_bytes"] += peer.splitter.flush()
            peer.sock.close()
            self.counters["disconnects"] += 1

    def read(self, fd: int) -> list[bytes]:
        if self.server is not None and fd == self.server.fileno():
            try:
                conn, _ = self.server.accept()
            except OSError:
                return []
            if len(self.peers) >= MAX_PEERS:
                self.counters["refused_peers"] += 1
                conn.close()
            else:
                self._add(conn)
            return []
        peer = self.peers.get(fd)
        if peer is None:
            return []
        try:
            data = peer.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return []
        except OSError:
            data = b""
        if not data:
            self._drop(fd)
            return []
        before = peer.splitter.garbage
        frames = peer.splitter.feed(data)
        self.counters["garbage_bytes"] += peer.splitter.garbage - before
        return frames

    def send(self, unit: bytes) -> bool:
        for fd, peer in list(self.peers.items()):
            if len(peer.outbox) + len(unit) > TCP_OUTBOX:
                self.counters["send_dropped"] += 1  # the peer does not read fast enough
                continue
            peer.outbox += unit
            self._flush(fd, peer)
        return bool(self.peers)

    def _flush(self, fd: int, peer: _TcpPeer) -> None:
        try:
            n = peer.sock.send(peer.outbox)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._drop(fd)
            return
        del peer.outbox[:n]

    def close(self) -> None:
        for fd in list(self.peers):
            self._drop(fd)
        if self._connecting is not None:
            self._connecting.close()
        if self.server is not None:
            self.server.close()


def open_endpoint(spec: EndpointSpec, frames: bool = False) -> Endpoint:
    """Open (bind, listen) the endpoint; OSError (e.g. the port is taken) propagates."""
    return UdpEndpoint(spec, frames) if spec.kind.startswith("udp") else TcpEndpoint(spec)
