"""Event-loop lag with the live estimator on the loop vs in its worker thread (``estimator.worker``).

    python benchmarks/estimator_loop_lag.py [--seconds 20] [--speed 4]

An asyncio program (like the MAVSDK mission runner) receives a simulated flight's MAVLink stream
(paper-s1, every IMU sample at 250 Hz, attitude, velocity, ESC telemetry: ~360 messages per
simulated second) at ``--speed`` times real time, in 10 ms bursts, and runs a 100 Hz tick (the
setpoint loop) beside it. Printed for both ways of running the estimator: the tick's lateness
(median, 99th percentile, worst, ms; each tick against the one before) and what the estimator
processed. The compiled kernels are loaded before either run. Inline, every message
is handled on the loop (``LiveCore.handle``); with the worker the loop only queues it.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from estimator_stream import autopilot_messages, over_the_wire, record  # noqa: E402

from estimator.live import LiveConfig, LiveCore
from estimator.worker import (
    EstimatorWorker,  # noqa: E402
    warm_up,  # noqa: E402
)
from vehicle.vehicle_file import load_vehicle  # noqa: E402


async def _run(stream: list, times: np.ndarray, speed: float, worker: bool) -> tuple[np.ndarray, str]:
    core = LiveCore(LiveConfig(vehicle=load_vehicle()))
    w = EstimatorWorker(core, warm=False) if worker else None
    if w is not None:
        w.start()
    lags: list[float] = []
    done = asyncio.Event()

    async def tick() -> None:
        nxt = time.monotonic()
        while not done.is_set():
            nxt += 0.01
            await asyncio.sleep(max(0.0, nxt - time.monotonic()))
            now = time.monotonic()
            lags.append(now - nxt)
            nxt = max(nxt, now - 0.01)  # a late tick does not make the following ones late

    async def feed() -> None:
        t0 = time.monotonic()
        i = 0
        while i < len(stream):
            now = (time.monotonic() - t0) * speed
            while i < len(stream) and times[i] <= now:
                if w is not None:
                    w.submit(stream[i])
                else:
                    core.handle(stream[i])
                i += 1
            await asyncio.sleep(0.01)
        done.set()

    await asyncio.gather(tick(), feed())
    if w is not None:
        w.stop(5.0)
        c = w.counts
        what = (f"processed {c['processed']}, IMU thinned {c['decimated_imu']}, dropped {c['dropped_imu']} IMU + "
                f"{c['dropped_other']} other")  # fmt: skip
    else:
        what = f"processed {len(stream)} (all, on the loop)"
    return np.array(lags) * 1e3, what + f"; filter steps {core.est.accepted['imu']}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--speed", type=float, default=4.0)
    args = ap.parse_args(argv)
    f = record(args.seconds)
    timed = autopilot_messages(f)
    stream = over_the_wire([(1, 1, timed)])
    times = np.array([t for t, _ in timed])
    warm_up(LiveConfig(vehicle=load_vehicle()))  # load the compiled kernels before timing
    print(f"{len(stream)} messages over {args.seconds:g} s of flight at {args.speed:g}x; 100 Hz tick lateness, ms")
    for worker in (False, True):
        lag, what = asyncio.run(_run(stream, times, args.speed, worker))
        name = "worker thread" if worker else "on the loop  "
        print(f"  {name}: median {np.median(lag):6.2f}  p99 {np.percentile(lag, 99):6.2f}  worst {lag.max():7.2f}"
              f"  ({what})", flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
