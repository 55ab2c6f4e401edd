"""Soak: SITL + live estimator + back-to-back missions for a long time at speed 1 (issue 14.8).

Starts ``windseek sitl open-field --speed 1 --forward`` and ``windseek estimator`` on ephemeral UDP
ports, then flies ``windseek mission --wind mavlink`` missions one after another (each arms, takes
off, searches, lands at its declaration and disarms; the next starts from there) until
``--minutes`` have passed. Every ``--sample-s`` it reads the resident memory (VmRSS) of the SITL
and the estimator; at the end it prints, per process, the memory at the start (after a warm-up),
at the end, the growth and the least-squares growth rate (MB per hour), and the message counts
(the SITL's received and sent MAVLink messages, the estimator's WIND_COV published), with every
mission's outcome.

Usage: ``python benchmarks/soak.py [--minutes 60] [--sample-s 10]``.
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def windseek(*args: str) -> list[str]:
    return [sys.executable, "-m", "windseek.cli", *args]


def rss_mb(pid: int) -> float:
    """Resident memory of a process, MB (NaN once it is gone)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return float("nan")
    m = re.search(r"VmRSS:\s+(\d+) kB", text)
    return int(m.group(1)) / 1024.0 if m else float("nan")


def growth(samples: list[tuple[float, float]], warmup_s: float) -> dict[str, float]:
    """Start (after the warm-up), end, growth and least-squares slope (MB/h) of (t s, MB) samples."""
    pts = np.array([(t, m) for t, m in samples if t >= warmup_s and np.isfinite(m)])
    if len(pts) < 2:
        return {"start_mb": float("nan"), "end_mb": float("nan"), "growth_mb": float("nan"), "mb_per_h": float("nan")}
    slope = float(np.polyfit(pts[:, 0], pts[:, 1], 1)[0]) * 3600.0
    return {"start_mb": round(float(pts[0, 1]), 1), "end_mb": round(float(pts[-1, 1]), 1),
            "growth_mb": round(float(pts[-1, 1] - pts[0, 1]), 2), "mb_per_h": round(slope, 2)}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--sample-s", type=float, default=10.0)
    ap.add_argument("--warmup-s", type=float, default=120.0, help="memory before this is start-up, not growth")
    args = ap.parse_args()
    p_est, p_mis = free_udp_port(), free_udp_port()
    sitl = subprocess.Popen(windseek("sitl", "open-field", "--speed", "1", "--udp-bind", "127.0.0.1:0", "--udp",
                                     f"127.0.0.1:{p_est}", f"127.0.0.1:{p_mis}", "--forward"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
    est = subprocess.Popen(windseek("estimator", "--connect", f"udpin://127.0.0.1:{p_est}", "--imu-average", "2",
                                    "--link-timeout", "3600", "--json"),
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)  # fmt: skip
    t0 = time.monotonic()
    end = t0 + 60.0 * args.minutes
    mem: dict[str, list[tuple[float, float]]] = {"sitl": [], "estimator": []}
    missions: list[dict] = []
    next_sample = t0
    try:
        while time.monotonic() < end:
            mis = subprocess.Popen(windseek("mission", "--connect", f"udpin://127.0.0.1:{p_mis}", "--strategy",
                                            "surge-cast", "--wind", "mavlink", "--time-limit", "240", "--json"),
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)  # fmt: skip
            while mis.poll() is None:
                now = time.monotonic()
                if now >= next_sample:
                    next_sample += args.sample_s
                    mem["sitl"].append((now - t0, rss_mb(sitl.pid)))
                    mem["estimator"].append((now - t0, rss_mb(est.pid)))
                if now > end + 600.0:
                    mis.kill()
                time.sleep(0.5)
            out = mis.stdout.read() if mis.stdout else ""
            r = json.loads(out.strip().splitlines()[-1]) if out.strip() else {"cause": f"exit {mis.returncode}"}
            missions.append({"t_min": round((time.monotonic() - t0) / 60, 1), "cause": r.get("cause"),
                             "disarmed": r.get("disarmed"), "time_s": r.get("time_s")})  # fmt: skip
            print(f"mission {len(missions)}: {missions[-1]}", flush=True)
    finally:
        for p in (est, sitl):
            p.send_signal(signal.SIGTERM)
        est_out = est.communicate(timeout=30)[0]
        sitl_err = sitl.communicate(timeout=30)[1]
    m = re.search(r"rx (\d+) msgs \((\d+) bad\), tx (\d+) msgs", sitl_err)
    est_json = json.loads(est_out.strip().splitlines()[-1]) if est_out.strip() else {}
    print(f"# soak: {args.minutes:g} min at speed 1, {len(missions)} missions, "
          f"{sum(1 for x in missions if x['cause'] == 'declared')} declared")  # fmt: skip
    for name, samples in mem.items():
        print(f"{name}: memory {growth(samples, args.warmup_s)}")
    if m:
        print(f"sitl: rx {m.group(1)} msgs ({m.group(2)} bad), tx {m.group(3)} msgs")
    keys = ("wind_cov_published", "accepted", "rejected", "restarts")
    print(f"estimator: {json.dumps({k: est_json.get(k) for k in keys})}")


if __name__ == "__main__":
    main()
