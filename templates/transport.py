"""Template: a byte pipe for the SITL's MAVLink endpoint (copy, rename, fill in).

A transport knows nothing about MAVLink: the endpoint polls :meth:`fds`, calls :meth:`read` when one
is readable and :meth:`write` to send. It must never block: a full buffer drops the frame and counts
it. This one is a Unix-domain datagram socket (a local IPC link to a co-located program).

Plug it in: ``SitlLink(sim, [UnixDatagramTransport("/tmp/windseek.sock", "/tmp/client.sock")])``.
"""

from __future__ import annotations

import contextlib
import os
import socket

from sitl.link.transports import Transport


class UnixDatagramTransport(Transport):
    """One Unix datagram socket at ``path`` sending to the peer socket at ``peer``."""

    def __init__(self, path: str, peer: str) -> None:
        super().__init__()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        self.path, self.peer = path, peer
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(path)
        self.sock.setblocking(False)
        self.name = f"unix:{path}"

    def fds(self) -> list[int]:
        return [self.sock.fileno()]

    def read(self, fd: int) -> bytes:
        try:
            data = self.sock.recv(65536)
        except BlockingIOError:
            return b""
        self.stats.rx_bytes += len(data)
        return data

    def write(self, data: bytes) -> None:
        try:
            self.sock.sendto(data, self.peer)
            self.stats.tx_bytes += len(data)
        except OSError:  # no peer yet, or its buffer is full: drop and count, never block
            self.stats.tx_errors += 1

    def close(self) -> None:
        self.sock.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
