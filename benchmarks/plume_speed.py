"""Plume cost benchmark: concentration sample and puff update with 1,000 / 10,000 puffs.

Prints medians in microseconds and the implied wall time per simulated second at the
default plume update rate and chemical-sensor rate, against the budget of a simulator
running 500 Hz physics at 100x real time (10 ms of wall time per simulated second).

Conventions: SI units, NED frame, wind = air-mass velocity NED; release in g/s,
concentration in mg/m^3. Seeded: the plume and wind are identical run to run.

Run: /work/venv/bin/python benchmarks/plume_speed.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from sitl.world.chem_sensor import ChemSensorConfig
from sitl.world.plume import PlumeConfig, PuffPlume, Source
from sitl.world.wind import KaimalTurbulence, SteadyWind, WindField

SEED = 2024
REALTIME_FACTOR = 100.0
BUDGET_US_PER_SIM_S = 1e6 / REALTIME_FACTOR  # wall time available per simulated second
WIND_SPEED_M_S = 3.0
FILL_TIME_S = 100.0  # puffs live ~this long before the cap bites (10 Hz * 100 s = 1000)


def _median_us(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        times.append(time.perf_counter_ns() - t0)
    return statistics.median(times) / 1000.0


def _filled_plume(n_puffs: int) -> PuffPlume:
    """Plume whose cap is reached: puff rate chosen so the cap fills in FILL_TIME_S."""
    wind = WindField(
        SteadyWind((WIND_SPEED_M_S, 0.0, 0.0)),
        KaimalTurbulence(sigma_u=0.3),
        seed=SEED,
    )
    cfg = PlumeConfig(
        sources=(Source((0.0, 0.0, -2.0), 1.0),),
        stability="D",
        puff_rate_hz=n_puffs / FILL_TIME_S,
        max_puffs=n_puffs,
    )
    plume = PuffPlume(cfg, wind, seed=SEED)
    dt = 1.0 / cfg.update_rate_hz
    for i in range(round((FILL_TIME_S + 10.0) * cfg.update_rate_hz)):
        plume.step(i * dt, dt)
    return plume


def main() -> None:
    update_hz = PlumeConfig(sources=()).update_rate_hz
    sensor_hz = ChemSensorConfig().sample_rate_hz
    print(f"budget at {REALTIME_FACTOR:.0f}x real time: {BUDGET_US_PER_SIM_S:.0f} us per sim s")
    print(f"default plume update {update_hz:.0f} Hz, sensor {sensor_hz:.0f} Hz")
    for n in (1_000, 10_000):
        plume = _filled_plume(n)
        dt = 1.0 / update_hz
        t = [plume.t]

        def update(plume=plume, t=t, dt=dt) -> None:
            plume.step(t[0], dt)
            t[0] += dt

        point = np.array([40.0, 0.0, -2.0])
        update_us = _median_us(update, 200)
        conc_us = _median_us(lambda plume=plume, point=point: plume.concentration(point), 2000)
        per_sim_s = update_hz * update_us + sensor_hz * conc_us
        print(
            f"{len(plume.puffs):6d} puffs: update {update_us:8.1f} us, one-point sample "
            f"{conc_us:7.1f} us -> {per_sim_s / 1000.0:6.2f} ms per sim s "
            f"({100.0 * per_sim_s / BUDGET_US_PER_SIM_S:5.1f} % of the 100x budget)"
        )
        # A recorded map slice (the recorder's 2 m grid): the first 60 m downwind of the source, 60 m
        # wide. Puffs further downwind are culled against the grid's box before the per-point sums.
        xs, ys = np.arange(0.0, 60.1, 2.0), np.arange(-30.0, 30.1, 2.0)
        grid = np.array([[x, y, -2.0] for x in xs for y in ys])
        grid_us = _median_us(lambda plume=plume, grid=grid: plume.concentration(grid), 50)
        print(f"{'':6s}        slice of {len(grid)} points {grid_us:8.1f} us ({1000.0 * grid_us / len(grid):.0f} ns "
              f"per point)")

if __name__ == "__main__":
    main()
