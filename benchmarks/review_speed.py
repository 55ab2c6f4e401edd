"""Speed of ``windseek review``: reading (MB/s, samples/s), the estimator re-run and the recording, for
.tlog, .ulg and .bin, on the real third-party logs and on ~100 MB logs made from them.

    .venv/bin/python benchmarks/review_speed.py [--logs DIR] [--big-mb 100] [--no-big]

Per file it prints the stage times (process CPU seconds, wall in brackets), the reading throughput
in MB/s and decoded samples/s (rows of every time series), the estimator's IMU steps/s, and the
peer's reading time in the same run with the ratio: pymavlink's own reader
(``mavutil.mavlink_connection(...).recv_match()`` over every message) for .tlog and .bin, pyulog
loading every topic for .ulg. Interpreter start-up and imports (``windseek`` imports every
subcommand: about 3 s of CPU here) are not included; they are printed once.

The ~100 MB logs: the .tlog and .bin repeated end to end (valid files whose clock restarts with
every copy: reading speed only), and a ULog re-written by pyulog with the hover log's topics tiled
65 times on a continuous clock (a 33-minute log with 65 take-offs), reviewed in full.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import subprocess
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pymavlink import mavutil  # noqa: E402
from pyulog import ULog  # noqa: E402

from review.convert import read_flight  # noqa: E402
from review.estimate import run_estimator  # noqa: E402
from review.rrd import write_rrd  # noqa: E402
from review.summary import missing_inputs  # noqa: E402
from review.trust import trust_mask  # noqa: E402
from vehicle.vehicle_file import load_vehicle  # noqa: E402

LOG_NAMES = ["ardupilot-quadplane-sitl.tlog", "px4-bench-never-armed.ulg", "px4-sitl-quad-hover.ulg",
             "px4-vtol-short-hop.ulg", "ardupilot-dataflash-excerpt.BIN"]  # fmt: skip


def timed(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    """(result, CPU s, wall s)."""
    c0, w0 = time.process_time(), time.perf_counter()
    out = fn()
    return out, time.process_time() - c0, time.perf_counter() - w0


def peer_read(path: Path, kind: str) -> int:
    """Read every message with the reference library: the peer of the review's reader (its prints muted)."""
    with contextlib.redirect_stdout(io.StringIO()):
        return _peer_read(path, kind)


def _peer_read(path: Path, kind: str) -> int:
    if kind == "ulog":
        u = ULog(str(path))
        return sum(len(d.data["timestamp"]) for d in u.data_list)
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    n = 0
    while conn.recv_match() is not None:
        n += 1
    conn.close()
    return n


def review_stages(path: Path, out: Path, full: bool = True) -> dict[str, float]:
    """Time the review's stages on one file (CPU s and wall s per stage)."""
    params = load_vehicle("nasa-quad")
    fd, c_read, w_read = timed(lambda: read_flight(path, "auto", params.rotor_speed_max_rad_s))
    r: dict[str, float] = {"mb": path.stat().st_size / 1e6, "read_cpu": c_read, "read_wall": w_read,
                           "samples": float(sum(len(s) for s in fd.all_series()))}  # fmt: skip
    r["est_cpu"] = r["est_wall"] = r["write_cpu"] = r["write_wall"] = r["imu_steps"] = 0.0
    if not full:
        return r
    missing, can = missing_inputs(fd)
    track = trust = None
    if can:
        track, r["est_cpu"], r["est_wall"] = timed(lambda: run_estimator(fd, params))
        trust = trust_mask(fd, track, 5.0, 1.0)
        r["imu_steps"] = float(track.imu_steps)
        r["decimated"] = float(track.decimated)
    ok = None if trust is None else trust.ok
    _, r["write_cpu"], r["write_wall"] = timed(lambda: write_rrd(fd, track, ok, out, missing))
    return r


def tiled_ulog(src: Path, dst: Path, copies: int) -> None:
    """Write a ULog with every topic of ``src`` repeated ``copies`` times on a continuous clock (pyulog)."""
    u = ULog(str(src))
    span = u.last_timestamp - u.start_timestamp + 1_000_000
    for d in u.data_list:
        n = len(d.data["timestamp"])
        for k, v in d.data.items():
            reps = np.tile(v, copies)
            if k == "timestamp":
                reps = reps + np.repeat(np.arange(copies, dtype=np.uint64) * np.uint64(span), n)
            d.data[k] = reps
    u.logged_messages.clear()
    u.write_ulog(str(dst))


def repeated(src: Path, dst: Path, copies: int) -> None:
    data = src.read_bytes()
    with dst.open("wb") as f:
        for _ in range(copies):
            f.write(data)


def row(name: str, r: dict[str, float], peer: tuple[float, float] | None) -> str:
    total_cpu = r["read_cpu"] + r["est_cpu"] + r["write_cpu"]
    total_wall = r["read_wall"] + r["est_wall"] + r["write_wall"]
    steps = f"{r['imu_steps'] / r['est_cpu']:8.0f}" if r["est_cpu"] > 0 else "       -"
    p = "        -        -" if peer is None else f"{peer[0]:8.2f} {peer[0] / max(r['read_cpu'], 1e-9):7.1f}x"
    return (f"{name:34s} {r['mb']:7.2f} {r['read_cpu']:7.2f} {r['mb'] / max(r['read_cpu'], 1e-9):7.1f} "
            f"{r['samples'] / max(r['read_cpu'], 1e-9):10.0f} {r['est_cpu']:8.2f} {steps} {r['write_cpu']:7.2f} "
            f"{total_cpu:8.2f} ({total_wall:6.1f}) {p}")  # fmt: skip


HEADER = (f"{'file':34s} {'MB':>7s} {'read s':>7s} {'MB/s':>7s} {'samples/s':>10s} {'est. s':>8s} {'IMU/s':>8s} "
          f"{'write s':>7s} {'total s':>8s} {'(wall)':>8s} {'peer s':>8s} {'ratio':>8s}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", type=Path, default=next((p for p in (ROOT.parent / "shared/data/logs",
                    Path("/work/shared/data/logs")) if p.is_dir()), None))  # fmt: skip
    ap.add_argument("--big-mb", type=float, default=100.0, help="size of the made-up big logs (MB)")
    ap.add_argument("--no-big", action="store_true", help="only the real logs")
    ap.add_argument("--work", type=Path, default=Path("/tmp/windseek-review-speed"))
    args = ap.parse_args()
    if args.logs is None:
        sys.exit("review_speed: no logs folder (give --logs DIR)")
    args.work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "windseek.cli", "--help"], stdout=subprocess.DEVNULL, check=True)
    print(f"windseek start-up (python -m windseek.cli --help): {time.perf_counter() - t0:.1f} s wall")
    review_stages(args.logs / "px4-vtol-short-hop.ulg", args.work / "warm-up.rrd")  # numba caches, lazy imports
    print("CPU seconds per stage (process time); 'peer s' = the reference reader on the same file, ratio = peer / ours")
    print(HEADER)
    for name in LOG_NAMES:
        path = args.logs / name
        kind = {".tlog": "tlog", ".ulg": "ulog"}.get(path.suffix.lower(), "dataflash")
        r = review_stages(path, args.work / f"{name}.rrd")
        _, pc, _ = timed(partial(peer_read, path, kind))
        print(row(name, r, (pc, 0.0)), flush=True)
    if args.no_big:
        return
    for name, how, full in (("ardupilot-quadplane-sitl.tlog", "repeat", False),
                            ("ardupilot-dataflash-excerpt.BIN", "repeat", False),
                            ("px4-sitl-quad-hover.ulg", "tile", True)):  # fmt: skip
        src = args.logs / name
        copies = max(1, int(round(args.big_mb * 1e6 / src.stat().st_size)))
        dst = args.work / f"big-{copies}x-{name}"
        if not dst.exists():
            (tiled_ulog if how == "tile" else repeated)(src, dst, copies)
        kind = {".tlog": "tlog", ".ulg": "ulog"}.get(dst.suffix.lower(), "dataflash")
        r = review_stages(dst, args.work / f"{dst.name}.rrd", full=full)
        _, pc, _ = timed(partial(peer_read, dst, kind))
        label = f"{copies}x {name}" + ("" if full else " (read)")
        print(row(label[:34], r, (pc, 0.0)) + (" decimated" if r.get("decimated") else ""), flush=True)


if __name__ == "__main__":
    main()
