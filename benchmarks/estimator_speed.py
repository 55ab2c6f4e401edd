"""Microseconds per wind-estimator step (predict + accelerometer update), and with a GNSS update.

    python benchmarks/estimator_speed.py [--steps 5000]

Both presets (``EstimatorConfig.preset``): ``calibrated`` (z accel bias state) and
``uncalibrated`` (force-scale state); 7 states each.

Input data: recorded paper-s1 sensor samples (250 Hz IMU, 50 Hz ESC, 10 Hz GNSS), replayed
into a fresh estimator after a warm-up run (numba compiled). Goal: <= 400 us per step on the
project machine, i.e. ten-fold headroom at 250 Hz.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from windseek import numba_cache  # before any kernel module

numba_cache.configure()
from estimator.ukf import PRESETS, EstimatorConfig, WindEstimator
from sitl.scenario import load_scenario
from sitl.simulation import T_QUAT, Simulation


def record(seconds: float) -> tuple[np.ndarray, list, list, list]:
    sim = Simulation(load_scenario("paper-s1").with_duration(seconds), seed=3, record_truth=True)
    sim.run(seconds)
    out = sim.drain()
    return sim.truth_array(), out["imu"], out["esc"], out["gnss"]


def replay(truth, imu, esc, gnss, n: int, preset: str = "uncalibrated") -> tuple[float, float]:
    """Returns (us per IMU step incl. its share of ESC/GNSS, us per GNSS update alone)."""
    est = WindEstimator(load_vehicle_from_sim(), EstimatorConfig.preset(preset))
    ei = gi = 0
    t_gnss = 0.0
    n_gnss = 0
    t0 = time.perf_counter()
    for k in range(min(n, len(imu))):
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
    total = time.perf_counter() - t0
    return 1e6 * total / min(n, len(imu)), 1e6 * t_gnss / max(n_gnss, 1)


def load_vehicle_from_sim():
    from vehicle.params import load_vehicle

    return load_vehicle()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=5000)
    args = ap.parse_args(argv)
    data = record(args.steps / 250.0 + 1.0)
    for preset in PRESETS:
        replay(*data, n=500, preset=preset)  # warm-up: numba compilation and caches
        us, us_gnss = replay(*data, n=args.steps, preset=preset)
        print(f"wind UKF ({preset}): {us:.0f} us per IMU step (predict + accel update + outputs, incl. ESC/GNSS "
              f"share); GNSS update alone {us_gnss:.0f} us; goal <= 400 us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
