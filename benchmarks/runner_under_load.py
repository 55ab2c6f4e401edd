"""The MAVSDK mission runner against the SITL while other processes burn every core (issue 14.1).

For each load level (0 = an idle machine, then N busy-loop processes), in the same run: start
``windseek sitl open-field --speed S`` on ephemeral UDP ports, fly ``windseek mission --strategy
surge-cast --wind estimated --json`` against it, and print what the runner kept up with:

- the mission's outcome (cause, declared, landed, disarmed) and its wall time;
- setpoint and strategy-tick rates (per second of vehicle time; 10 Hz nominal), skipped ticks;
- the event loop's lag (how late a 20 ms sleep woke: max and 99th percentile, ms);
- the live estimator's IMU samples accepted, decimated and dropped (counted, never silent);
- the machine's load average during the run.

Usage: ``python benchmarks/runner_under_load.py [--burners 0 4 8] [--speed 2] [--seed 1]``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BURN = "import time\nwhile True:\n    sum(i * i for i in range(10000))\n"


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def windseek(*args: str) -> list[str]:
    return [sys.executable, "-m", "windseek.cli", *args]


def one_run(burners: int, speed: float, seed: int, wall_limit: float) -> dict:
    """One mission with ``burners`` busy processes running; the runner's figures."""
    burn = [subprocess.Popen([sys.executable, "-c", BURN]) for _ in range(burners)]
    port = free_udp_port()
    sitl = subprocess.Popen(windseek("sitl", "open-field", "--speed", f"{speed:g}", "--seed", str(seed),
                                     "--udp-bind", "127.0.0.1:0", "--udp", f"127.0.0.1:{port}"),
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)  # fmt: skip
    try:
        assert sitl.stdout is not None
        sitl.stdout.readline()  # the SITL prints its first line once its link is up
        load0 = os.getloadavg()[0]
        t0 = time.monotonic()
        mis = subprocess.run(windseek("mission", "--connect", f"udpin://127.0.0.1:{port}", "--strategy", "surge-cast",
                                      "--wind", "estimated", "--speed-hint", f"{speed:g}", "--seed", str(seed),
                                      "--json"),
                             capture_output=True, text=True, timeout=wall_limit, cwd=ROOT)  # fmt: skip
        wall = time.monotonic() - t0
        load1 = os.getloadavg()[0]
    except subprocess.TimeoutExpired:
        return {"burners": burners, "cause": f"no result within {wall_limit:g} s (hung)", "wall_s": wall_limit}
    finally:
        sitl.terminate()
        sitl.communicate(timeout=20)
        for b in burn:
            b.kill()
            b.wait()
    lines = mis.stdout.strip().splitlines()
    if not lines:
        return {"burners": burners, "cause": f"no JSON (exit {mis.returncode}): {mis.stderr[-300:]}", "wall_s": wall}
    r = json.loads(lines[-1])
    est = r.get("estimator", {})
    return {
        "burners": burners, "load": round(max(load0, load1), 1), "cause": r["cause"], "wall_s": round(wall, 1),
        "landed": r["landed"], "disarmed": r["disarmed"], "setpoint_hz": r["setpoint_rate_hz"],
        "tick_hz": r["tick_rate_hz"], "ticks_skipped": r.get("ticks_skipped", 0),
        "lag_max_ms": r.get("loop_lag_max_ms"), "lag_p99_ms": r.get("loop_lag_p99_ms"),
        "imu_accepted": est.get("accepted", {}).get("imu", 0), "imu_decimated": est.get("imu_decimated", 0),
        "imu_dropped": est.get("dropped", 0), "mission_s": r.get("mission_time_s"),
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--burners", type=int, nargs="+", default=[0, 4, 8], help="busy processes per run")
    ap.add_argument("--speed", type=float, default=2.0, help="the SITL's speed factor")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--wall-limit", type=float, default=600.0, help="wall seconds before a run counts as hung")
    args = ap.parse_args()
    # A SIGTERM (a timeout around the script) still runs one_run's cleanup: no busy process outlives it.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    print(f"# runner under load: open-field, surge-cast, estimated wind, SITL speed {args.speed:g}, "
          f"{os.cpu_count()} cores")  # fmt: skip
    cols = ("burners", "load", "cause", "wall_s", "mission_s", "setpoint_hz", "tick_hz", "ticks_skipped",
            "lag_max_ms", "lag_p99_ms", "imu_accepted", "imu_decimated", "imu_dropped", "landed", "disarmed")
    print(" | ".join(cols))
    for n in args.burners:
        row = one_run(n, args.speed, args.seed, args.wall_limit)
        print(" | ".join(str(row.get(c, "")) for c in cols), flush=True)


if __name__ == "__main__":
    main()
