"""Microseconds per wind-estimator step (predict + accelerometer update + outputs), and a GNSS update.

    python benchmarks/estimator_speed.py [--steps 5000] [--repeats 3] [--before REV] [--no-peer]

Both presets (``EstimatorConfig.preset``): ``calibrated`` (z accel bias state) and
``uncalibrated`` (force-scale state); 7 states each.

Input data: recorded paper-s1 sensor samples (250 Hz IMU, 50 Hz ESC, 10 Hz GNSS), replayed
into a fresh estimator after a warm-up run (numba compiled). One step = set_rotor_speeds (its
share), set_attitude, imu (predict + accelerometer update), gnss_velocity (its share), and
estimate(): what a live consumer does per IMU sample. Printed per step: wall time
(perf_counter) and CPU time of the process (process_time; on a shared machine the wall time
also counts the time other jobs held the core), best of ``--repeats`` runs. Goal (issue 21):
<= 100 us per step.

Peers, timed in the same run on the same data:
- ``--before REV``: the estimator package as it was at git revision REV (e.g. the commit before
  the numba filter), loaded from ``git show`` into a temporary folder. Needs the git history.
- filterpy's UnscentedKalmanFilter on the same model (``estimator.reference``, the yardstick of
  ``tests/test_estimator_reference.py``), calibrated preset without its transient boost.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from estimator.ukf import PRESETS, EstimatorConfig, WindEstimator
from sitl.scenario import load_scenario
from sitl.simulation import T_QUAT, Simulation
from vehicle.frames import quat_to_dcm
from vehicle.vehicle_file import load_vehicle

ROOT = Path(__file__).resolve().parent.parent


def record(seconds: float) -> tuple[np.ndarray, list, list, list]:
    sim = Simulation(load_scenario("paper-s1").with_duration(seconds), seed=3, record_truth=True)
    sim.run(seconds)
    out = sim.drain()
    return sim.truth_array(), out["imu"], out["esc"], out["gnss"]


def current(preset: str) -> WindEstimator:
    return WindEstimator(load_vehicle(), EstimatorConfig.preset(preset))


def replay(make: Any, data: tuple, n: int, preset: str) -> tuple[float, float, float]:
    """(wall us per step, CPU us per step, wall us per GNSS update alone) of ``make(preset)``."""
    truth, imu, esc, gnss = data
    est = make(preset)
    ei = gi = 0
    t_gnss = 0.0
    n_gnss = 0
    n = min(n, len(imu))
    c0, t0 = time.process_time(), time.perf_counter()
    for k in range(n):
        t, acc, gyr = imu[k]
        while ei < len(esc) and esc[ei][0] <= t:
            est.set_rotor_speeds(esc[ei][0], esc[ei][1])
            ei += 1
        est.set_attitude(t, truth[k, T_QUAT])
        est.imu(t, acc, gyr)
        while gi < len(gnss) and gnss[gi].t + 0.1 <= t:
            g0 = time.perf_counter()
            est.gnss_velocity(gnss[gi].t, gnss[gi].vel_ned)
            t_gnss += time.perf_counter() - g0
            n_gnss += 1
            gi += 1
        est.estimate()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return 1e6 * wall / n, 1e6 * cpu / n, 1e6 * t_gnss / max(n_gnss, 1)


def load_before(rev: str) -> Any:
    """``WindEstimator`` and ``EstimatorConfig`` of the estimator package at git revision ``rev``."""
    files = subprocess.run(["git", "-C", str(ROOT), "ls-tree", "--name-only", rev, "estimator/"],
                           capture_output=True, text=True, check=True).stdout.split()  # fmt: skip
    tmp = Path(tempfile.mkdtemp(prefix="windseek-before-"))
    pkg = tmp / "estimator_before"
    pkg.mkdir()
    for f in files:
        src = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{f}"], capture_output=True, text=True,
                             check=True).stdout  # fmt: skip
        (pkg / Path(f).name).write_text(src.replace("from estimator.", "from estimator_before."))
    sys.path.insert(0, str(tmp))
    ukf = importlib.import_module("estimator_before.ukf")
    return lambda preset: ukf.WindEstimator(load_vehicle(), ukf.EstimatorConfig.preset(preset))


class _Reference:
    """filterpy's UnscentedKalmanFilter (``estimator.reference``) behind the estimator's input API."""

    def __init__(self, preset: str) -> None:
        from estimator.reference import FilterpyWindUKF

        cfg = EstimatorConfig.preset("calibrated", transient_wind_q_gain=1.0)
        e = WindEstimator(load_vehicle(), cfg)
        self.f = FilterpyWindUKF(e._p, cfg, e.x, e.P, e._q_density, e._i_scale, e._bias_idx)
        self.R = np.eye(3)
        self.w = np.zeros(4)
        self.t: float | None = None

    def set_rotor_speeds(self, t: float, w: np.ndarray) -> None:
        self.w = np.asarray(w, dtype=float)

    def set_attitude(self, t: float, q: np.ndarray) -> None:
        self.R = quat_to_dcm(np.asarray(q, dtype=float))

    def imu(self, t: float, acc: np.ndarray, gyr: np.ndarray) -> None:
        g = np.asarray(gyr, dtype=float)
        if self.t is not None:
            self.f.predict(t - self.t, self.R, g, self.w)
        self.f.update_accel(np.asarray(acc, dtype=float), self.R, g, self.w)
        self.t = t

    def gnss_velocity(self, t: float, v: np.ndarray) -> None:
        self.f.update_velocity(np.asarray(v, dtype=float), self.R)

    def estimate(self) -> np.ndarray:
        return np.asarray(self.f.ukf.x[3:6])


def best(make: Any, data: tuple, n: int, preset: str, repeats: int) -> tuple[float, float, float]:
    replay(make, data, 300, preset)  # warm-up: numba compilation and caches
    runs = [replay(make, data, n, preset) for _ in range(repeats)]
    return min(r[0] for r in runs), min(r[1] for r in runs), min(r[2] for r in runs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--before", metavar="REV", default=None, help="also time the estimator at git revision REV")
    ap.add_argument("--no-peer", action="store_true", help="skip filterpy's UnscentedKalmanFilter")
    args = ap.parse_args(argv)
    data = record(args.steps / 250.0 + 1.0)
    before = load_before(args.before) if args.before else None
    print("wind UKF, us per IMU step (predict + accel update + outputs, incl. ESC/GNSS share), best of "
          f"{args.repeats} x {args.steps} steps; goal <= 100 us")  # fmt: skip
    for preset in PRESETS:
        wall, cpu, g = best(current, data, args.steps, preset, args.repeats)
        line = f"  {preset:13s} now: {wall:6.1f} us wall, {cpu:6.1f} us CPU (GNSS update alone {g:.0f} us wall)"
        if before is not None:
            bw, bc, bg = best(before, data, args.steps, preset, args.repeats)
            line += f"; at {args.before}: {bw:6.1f} us wall, {bc:6.1f} us CPU (GNSS {bg:.0f}); {bc / cpu:.1f}x"
        print(line, flush=True)
    if not args.no_peer:
        n = min(args.steps, 1000)
        wall, cpu, g = best(_Reference, data, n, "calibrated", 1)
        print(f"  filterpy UnscentedKalmanFilter, same model (calibrated, {n} steps): {wall:6.1f} us wall, "
              f"{cpu:6.1f} us CPU (GNSS update alone {g:.0f} us)")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
