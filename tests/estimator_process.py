"""``windseek estimator`` as a subprocess fed over a real UDP socket (``tests/test_estimator_cli.py``,
``tests/test_estimator_px4_mag_cli.py``): start it, wait for it to listen, send a paced plan of frames, hand
every datagram it sends back to the caller, stop it with SIGTERM and return what it printed."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from link_support import free_port

ROOT = Path(__file__).resolve().parent.parent
Reply = Callable[[bytes], None]


def run_estimator(plan: list[tuple[float, bytes]], speed: float, on_datagram: Callable[[bytes, Reply], None],
                  extra_args: tuple[str, ...] = (), settle_s: float = 1.0) -> tuple[int, str, str]:  # fmt: skip
    """Send each packed frame of ``plan`` at its time / ``speed`` of wall clock (after the estimator says it is
    connecting, at most 120 s: it imports and loads its compiled kernels first), pass every datagram received
    to ``on_datagram(data, reply)`` (``reply`` sends bytes back to the estimator), then SIGTERM; returns
    (exit code, stdout, stderr)."""
    port = free_port()
    est = subprocess.Popen(
        [sys.executable, "-m", "windseek.cli", "estimator", "--connect", f"udpin://127.0.0.1:{port}",
         "--json", "--progress-every", "0", "--link-timeout", "5", "--duration", "60", *extra_args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(est.stderr.readline, "")), daemon=True)
    reader.start()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)

    def drain() -> None:
        while True:
            try:
                data, peer = sock.recvfrom(65536)
            except BlockingIOError:
                return
            on_datagram(data, lambda b, peer=peer: sock.sendto(b, peer))

    out = ""
    try:
        end = time.monotonic() + 120.0
        while not any("connecting on" in x for x in lines) and est.poll() is None and time.monotonic() < end:
            time.sleep(0.05)
        assert any("connecting on" in x for x in lines), lines
        wall0 = time.monotonic()
        for t, frame in plan:
            while time.monotonic() - wall0 < t / speed:
                drain()
                time.sleep(0.002)
            sock.sendto(frame, ("127.0.0.1", port))
        time.sleep(settle_s)
        drain()
    finally:
        est.send_signal(signal.SIGTERM)
        out = est.stdout.read() if est.wait(timeout=30) is not None else ""  # type: ignore[union-attr]
        reader.join(5.0)
        sock.close()
    return est.returncode, out, "".join(lines)
