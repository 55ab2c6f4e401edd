"""Lockstep speed of ArduCopter SITL with windseek as its JSON physics, and ArduCopter's own physics in the same run.

Per round, one run after the other, each with ArduCopter hovering at 10 m in GUIDED after an arm +
take-off through a pymavlink ground station on SERIAL0 (which reads everything, as MAVProxy does:
ArduPilot SITL pauses while that queue is full):

1. ``windseek sitl open-field --ardupilot`` (800 Hz frames, one UDP round trip each) + ArduCopter
   ``--model JSON --speedup 1000`` (as fast as the pair runs) with windseek's parameter file; once with
   windseek spinning between back-to-back frames (the default) and, with ``--no-spin`` too, once sleeping;
2. the peer: ArduCopter ``--model quad --speedup 1000``: ArduPilot's own multicopter physics inside the
   ArduPilot process (1200 Hz frames, no hand-off), ArduPilot's SITL defaults.

Printed per run, over ``--windows`` windows of ``--seconds`` wall seconds in hover: the speed (simulated
seconds per wall second, from ArduCopter's SYSTEM_TIME), the CPU per simulated millisecond of each
process and the load average; at the end the median per variant with its range and the ratio to the
peer. The speeds depend on the machine's load (2 shared cores here).

First it prints windseek's own work per frame in-process (no sockets, no second process).

Usage: ``WINDSEEK_ARDUPILOT_BIN=.../build/sitl/bin/arducopter python benchmarks/ardupilot_lockstep.py
[--seconds 10] [--windows 3] [--rounds 1] [--no-spin]``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from sitl.ardupilot.gcs import CopterGcs  # noqa: E402
from sitl.ardupilot.process import ArduCopterSitl, ardupilot_binary, free_instance, ports  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402

SCENARIO = "open-field"


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (all threads)."""
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


def _boot_s(g: CopterGcs) -> float:
    m = g.recv("SYSTEM_TIME", 10.0)
    if m is None:
        raise RuntimeError("no SYSTEM_TIME from ArduCopter")
    return m.time_boot_ms / 1000.0


def fly_and_measure(gcs_port: int, seconds: float, windows: int, pids: list[int]) -> list[dict[str, Any]]:
    g = CopterGcs(gcs_port)
    try:
        g.guided_takeoff(10.0)
        if g.recv("GLOBAL_POSITION_INT", 120.0, lambda p: p.relative_alt > 9000) is None:
            raise RuntimeError("did not reach 9 m")
        out = []
        for _ in range(windows):
            c0, s0, w0 = [cpu_s(p) for p in pids], _boot_s(g), time.monotonic()
            time.sleep(seconds)
            c1, s1, w1 = [cpu_s(p) for p in pids], _boot_s(g), time.monotonic()
            sim = s1 - s0
            cpu = [1e3 * (b - a) / sim for a, b in zip(c0, c1, strict=True)]
            out.append({"speed": sim / (w1 - w0), "cpu_us_per_sim_ms": cpu, "load": os.getloadavg()[0]})
        return out
    finally:
        g.close()


def _home() -> str:
    h = load_scenario(SCENARIO).sensors.home
    return f"{h.lat_deg:.7f},{h.lon_deg:.7f},{h.alt_m:g},0"


def run_windseek(binary: Path, seconds: float, windows: int, tmp: Path, spin: float) -> dict[str, Any]:
    n = free_instance()
    p = ports(n)
    summary = tmp / f"ws-{spin:g}.json"
    cmd = [sys.executable, "-m", "windseek.cli", "sitl", SCENARIO, "--ardupilot", "--ardupilot-port", str(p["json"]),
           "--ardupilot-mavlink", f"127.0.0.1:{p['peripheral']}", "--ardupilot-spin", f"{spin:g}",
           "--exit-summary", str(summary)]  # fmt: skip
    ws = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ap = ArduCopterSitl(binary, n, tmp / f"ap-{spin:g}", tmp / f"ap-{spin:g}.log", _home(), speedup=1000)
    try:
        time.sleep(1.0)
        ap.start()
        assert ap.proc is not None
        res = fly_and_measure(p["gcs"], seconds, windows, [ws.pid, ap.proc.pid])
    finally:
        ap.stop()
        ws.send_signal(signal.SIGTERM)
        ws.wait(30)
    s = json.loads(summary.read_text()) if summary.exists() else {}
    return {"windows": res, "summary": {k: s.get(k) for k in ("cpu_us_per_frame_windseek",
                                                                 "cpu_us_per_frame_windseek_with_spin", "frames")}}


def run_peer(binary: Path, seconds: float, windows: int, tmp: Path) -> dict[str, Any]:
    n = free_instance()
    ap = ArduCopterSitl(binary, n, tmp / "ap-quad", tmp / "ap-quad.log", _home(), speedup=1000, params=[],
                        model="quad")  # fmt: skip
    with ap:
        assert ap.proc is not None
        return {"windows": fly_and_measure(ports(n)["gcs"], seconds, windows, [ap.proc.pid])}


def bridge_us_per_frame(frames: int = 20000) -> float:
    """windseek's own work per ArduPilot frame in-process (servo packet decoded, outputs checked, one tick, the
    state line), CPU microseconds, after 2,000 warm-up frames: no sockets, no second process."""
    from sitl.ardupilot.bridge import ArduPilotBridge
    from sitl.ardupilot.json_protocol import parse_servo_packet, servo_packet

    b = ArduPilotBridge(load_scenario(SCENARIO), say=lambda _: None)
    raw = servo_packet(1, [1655] * 4 + [0] * 12)
    for _ in range(2000):
        b.on_servos(parse_servo_packet(raw))
        b.step()
    c0 = time.process_time()
    for _ in range(frames):
        b.on_servos(parse_servo_packet(raw))
        b.step()
    return 1e6 * (time.process_time() - c0) / frames


def _line(label: str, r: dict[str, Any]) -> None:
    for w in r["windows"]:
        cpu = " + ".join(f"{c:.0f}" for c in w["cpu_us_per_sim_ms"])
        print(f"  {label:<22} {w['speed']:6.2f}x   CPU per simulated ms: {cpu} us   load {w['load']:.1f}")
    if r.get("summary"):
        print(f"  {'':<22} windseek's exit summary: {r['summary']}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--windows", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--no-spin", action="store_true", help="also run windseek without spinning")
    a = ap.parse_args()
    binary = ardupilot_binary()
    if binary is None:
        print("set WINDSEEK_ARDUPILOT_BIN to a built arducopter (build/sitl/bin/arducopter)")
        return 2
    print(f"windseek's work per frame in-process: {bridge_us_per_frame():.1f} us (CPU)")
    variants: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        for r in range(a.rounds):
            print(f"round {r + 1}:")
            runs = [("windseek (spin)", lambda: run_windseek(binary, a.seconds, a.windows, tmp, 0.0005))]
            if a.no_spin:
                runs.append(("windseek (no spin)", lambda: run_windseek(binary, a.seconds, a.windows, tmp, 0.0)))
            runs.append(("ArduPilot's own quad", lambda: run_peer(binary, a.seconds, a.windows, tmp)))
            for label, fn in runs:
                res = fn()
                _line(label, res)
                variants.setdefault(label, []).extend(w["speed"] for w in res["windows"])
    print("median speed (range):")
    peer = statistics.median(variants["ArduPilot's own quad"])
    for label, v in variants.items():
        m = statistics.median(v)
        print(f"  {label:<22} {m:6.2f}x ({min(v):.2f}-{max(v):.2f}); ratio to ArduPilot's own quad {m / peer:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
