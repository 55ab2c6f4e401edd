"""Link proxy cost: CPU per forwarded UDP datagram of ``windseek link-proxy`` (its own process), with every
fault on and with none, against a bare Python UDP relay (select, recvfrom, sendto: the peer) measured in
the same run, at the same offered rate. A SITL at speed K sends about 100 K datagrams per second.

    python benchmarks/link_proxy_speed.py [--rate 3000] [--seconds 6]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RELAY = """
import select, socket, sys
a, b = int(sys.argv[1]), int(sys.argv[2])
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", a))
o = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
print("ready", flush=True)
while True:
    if select.select([s], [], [], 0.05)[0]:
        o.sendto(s.recv(65536), ("127.0.0.1", b))
"""
FAULTS = ["--loss", "0.3", "--dup", "0.1", "--reorder", "0.1", "--latency", "20", "--jitter", "10",
          "--bandwidth", "1e7"]  # fmt: skip


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(kind: str, rate: float, seconds: float) -> dict:
    a, b = free_port(), free_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", b))
    rx.setblocking(False)
    if kind == "relay":
        cmd = [sys.executable, "-c", RELAY, str(a), str(b)]
    else:
        cmd = [sys.executable, "-m", "windseek.cli", "link-proxy", f"udpin:127.0.0.1:{a}", f"udpout:127.0.0.1:{b}",
               "--json", "--progress-every", "0", *(FAULTS if kind == "proxy, all faults" else [])]  # fmt: skip
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    (p.stdout if kind == "relay" else p.stderr).readline()  # it is up
    tx, data, n, got = socket.socket(socket.AF_INET, socket.SOCK_DGRAM), bytes(300), int(rate * seconds), 0
    c0, t0 = cpu_s(p.pid), time.monotonic()
    for i in range(n):  # in bursts of 20, paced to the offered rate, draining the receiver in between
        tx.sendto(data, ("127.0.0.1", a))
        if i % 20 == 19:
            time.sleep(max(0.0, t0 + (i + 1) / rate - time.monotonic()))
            while True:
                try:
                    rx.recv(65536)
                    got += 1
                except BlockingIOError:
                    break
    time.sleep(0.5)
    c1 = cpu_s(p.pid)
    while True:
        try:
            rx.recv(65536)
            got += 1
        except BlockingIOError:
            break
    p.terminate()
    out, _ = p.communicate(timeout=10)
    handled = json.loads(out)["a->b"]["rx_units"] if kind != "relay" else got
    return {"kind": kind, "sent": n, "handled": handled, "delivered": got, "us_per_datagram": 1e6 * (c1 - c0) / n}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=3000.0, help="offered datagrams per second")
    ap.add_argument("--seconds", type=float, default=6.0)
    args = ap.parse_args()
    rows = [measure(k, args.rate, args.seconds) for k in ("relay", "proxy, no faults", "proxy, all faults")]
    peer = rows[0]["us_per_datagram"]
    print(f"offered {args.rate:g} datagrams/s of 300 B for {args.seconds:g} s; load average {os.getloadavg()[0]:.1f}")
    for r in rows:
        print(f"  {r['kind']:18s} CPU {r['us_per_datagram']:5.1f} us per datagram ({r['us_per_datagram'] / peer:.1f}x "
              f"the bare relay); received {r['handled']} of {r['sent']}, delivered {r['delivered']}")


if __name__ == "__main__":
    main()
