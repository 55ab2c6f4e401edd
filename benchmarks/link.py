"""Throughput and timing of the MAVLink endpoint (``windseek sitl`` in a subprocess, UDP).

Figures printed:

1. Out: MAVLink messages per wall-clock second the endpoint sends with the default streams, at
   speed 1 and at the highest speed factor of the ladder at which every stream keeps its rate
   (per simulated second within 5 %) and the simulation keeps pace with the wall clock.
2. In: PING requests per second the endpoint parses and answers while streaming at speed 1
   (a PING costs a full parse, dispatch and reply, like a command).
3. Jitter of the 50 Hz streams (ATTITUDE_QUATERNION, ESC_STATUS) at speed 1: standard deviation
   and 99th percentile of the wall-clock arrival interval minus its nominal 20 ms.

Usage: ``python benchmarks/link.py [--scenario paper-s1] [--seconds 4]``. The SITL runs in its
own process so the receiver does not compete with it for the GIL.
"""

from __future__ import annotations

import argparse
import socket
import struct
import subprocess
import sys
import time
from collections import Counter, defaultdict

import numpy as np

ID_ATTQ, ID_ESC, ID_PING = 31, 291, 4
# Default rates (Hz of simulation time) of the periodic and sample-driven streams.
EXPECTED = {0: 1, 1: 5, 245: 5, 30: 100, 31: 50, 32: 30, 33: 50, 242: 0.5, 74: 10, 147: 1, 141: 10, 105: 50,
            36: 10, 375: 10, 290: 1, 2: 1, 111: 1, 42: 1, 107: 250, 291: 50, 24: 10}  # fmt: skip


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def frames(buf: bytes) -> list[tuple[int, int]]:
    """(msgid, payload offset) of every MAVLink 2 frame in a datagram (v1 frames too)."""
    out = []
    i = 0
    n = len(buf)
    while i + 3 < n:
        if buf[i] == 0xFD:
            ln = buf[i + 1]
            mid = buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16
            out.append((mid, i + 10))
            i += 12 + ln + (13 if buf[i + 2] & 1 else 0)
        elif buf[i] == 0xFE:
            out.append((buf[i + 5], i + 6))
            i += 8 + buf[i + 1]
        else:
            i += 1
    return out


def start_sitl(scenario: str, speed: float, peer_port: int, bind_port: int) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "windseek.cli", "sitl", scenario, "--speed", str(speed),
           "--udp", f"127.0.0.1:{peer_port}", "--udp-bind", f"127.0.0.1:{bind_port}"]  # fmt: skip
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def receive(sock: socket.socket, seconds: float, ping_to: tuple[str, int] | None = None) -> dict:
    """Receive for ``seconds`` wall; optionally blast PINGs. Returns counts and arrival times."""
    counts: Counter[int] = Counter()
    arrivals: dict[int, list[float]] = defaultdict(list)
    pings_sent = 0
    boot_ms: list[int] = []
    ping = None
    if ping_to is not None:
        from wire.dialect import mavlink

        enc = mavlink.MAVLink(None, 255, 190)
        ping = mavlink.MAVLink_ping_message(0, 0, 0, 0)
    t0 = time.perf_counter()
    t_end = t0 + seconds
    sock.settimeout(0.001 if ping_to else 0.05)
    while (now := time.perf_counter()) < t_end:
        if ping is not None:
            for _ in range(20):
                ping.time_usec = int(now * 1e6)
                ping.seq = pings_sent & 0xFFFFFFFF
                sock.sendto(ping.pack(enc), ping_to)
                enc.seq = (enc.seq + 1) % 256
                pings_sent += 1
        try:
            while time.perf_counter() < t_end:
                data = sock.recv(65536)
                t = time.perf_counter()
                for mid, off in frames(data):
                    counts[mid] += 1
                    if mid in (ID_ATTQ, ID_ESC):
                        arrivals[mid].append(t)
                    if mid == ID_ATTQ:  # time_boot_ms: simulation time
                        boot_ms.append(struct.unpack_from("<I", data, off)[0])
        except (TimeoutError, BlockingIOError):
            pass
    sim_s = (boot_ms[-1] - boot_ms[0]) / 1000.0 if len(boot_ms) > 1 else 0.0
    return {"counts": counts, "arrivals": arrivals, "wall": time.perf_counter() - t0, "pings_sent": pings_sent,
            "sim_s": sim_s}  # fmt: skip


def session(scenario: str, speed: float, seconds: float, ping: bool = False) -> dict:
    port, bind = free_port(), free_port()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", port))
    proc = start_sitl(scenario, speed, port, bind)
    try:
        sock.settimeout(90.0)
        sock.recv(65536)  # first datagram: the SITL is up (numba caches loaded)
        receive(sock, 0.5)  # settle
        res = receive(sock, seconds, ("127.0.0.1", bind) if ping else None)
    finally:
        proc.terminate()
        proc.communicate(timeout=10)
        sock.close()
    c = res["counts"]
    sim_s = res["sim_s"]  # simulated seconds covered, from the time stamps of a 50 Hz stream
    res["msgs_per_s"] = sum(c.values()) / res["wall"]
    res["sim_per_wall"] = sim_s / res["wall"]
    res["rate_ok"] = all(
        abs(c[mid] / max(sim_s, 1e-9) - hz) <= 0.05 * hz + 1.0 / max(sim_s, 1e-9) for mid, hz in EXPECTED.items()
    )
    res["pace_ok"] = res["sim_per_wall"] >= 0.95 * speed
    return res


def jitter_ms(times: list[float], nominal_s: float) -> tuple[float, float]:
    d = (np.diff(np.asarray(times)) - nominal_s) * 1e3
    return float(np.std(d)), float(np.percentile(np.abs(d), 99))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="paper-s1")
    ap.add_argument("--seconds", type=float, default=4.0)
    args = ap.parse_args()

    r1 = session(args.scenario, 1.0, args.seconds)
    print(f"speed 1: out {r1['msgs_per_s']:.0f} msg/s, sim/wall {r1['sim_per_wall']:.3f}, "
          f"all streams at rate: {r1['rate_ok']}")  # fmt: skip
    for mid, name in ((ID_ATTQ, "ATTITUDE_QUATERNION"), (ID_ESC, "ESC_STATUS")):
        sd, p99 = jitter_ms(r1["arrivals"][mid], 1.0 / 50.0)
        print(f"  50 Hz {name}: interval jitter std {sd:.2f} ms, |dev| p99 {p99:.2f} ms")
    best = 1.0
    best_res = r1
    for speed in (2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0):
        r = session(args.scenario, speed, args.seconds)
        ok = r["rate_ok"] and r["pace_ok"]
        print(f"speed {speed:g}: out {r['msgs_per_s']:.0f} msg/s, sim/wall {r['sim_per_wall']:.2f}, "
              f"streams at rate {r['rate_ok']}, keeps pace {r['pace_ok']}")  # fmt: skip
        if not ok:
            break
        best, best_res = speed, r
    print(f"highest speed with every stream at rate: {best:g} ({best_res['msgs_per_s']:.0f} msg/s out)")
    rp = session(args.scenario, 1.0, args.seconds, ping=True)
    answered = rp["counts"][ID_PING]
    print(f"in at speed 1: {rp['pings_sent'] / rp['wall']:.0f} PING/s offered, {answered / rp['wall']:.0f} answered/s "
          f"while streaming {rp['msgs_per_s'] - answered / rp['wall']:.0f} msg/s")


if __name__ == "__main__":
    main()
