"""A worker process for a strategy's urban wind-field solve: the MAVSDK setpoint stream never waits for it.

The urban infotaxis (``mission/strategy_files/urban.toml``) solves windseek's urban diagnostic wind
field once per mission, after it has measured the inflow above the roofs (about 0.5 s of CPU,
``mission.strategies.ste_city``). In the in-process runner that happens inside the strategy's tick
(the lockstep simulator waits for it). Through MAVSDK the tick runs on the event loop that sends the
setpoints at 10 Hz, and PX4 leaves offboard after 1 s without one (COM_OF_LOSS_T). A thread does not
free the loop: the solve's numba and pyamg kernels hold the GIL (2026-12-06, the paper-s4 blocks:
event-loop lag up to 0.34 s with the solve in a thread, 0.95 s with it in the tick). So it runs in
one spawned worker process (no fork: the runner has threads), started before take-off, where its
imports and numba kernels are loaded by a warm-up solve of a one-building scene; the strategy hovers
in state ``solve-field`` until the result comes (at most ``ste_city.FIELD_SOLVE_LIMIT_S``). The
field is the same function of the same inflow and buildings as in the tick.
"""

from __future__ import annotations

import asyncio
import multiprocessing
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from mission.obstacles import Building, Obstacles
from mission.strategies.params import CommonParams
from toolchain import numba_cache


def warm_up() -> None:
    """In the worker: import the solver and load its kernels (a 10 m block in a 3 m/s wind, 4 m cells)."""
    from mission.strategies.ste_urban_field import build_plane

    block = Building(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]), 10.0, "warm-up")
    build_plane([block], np.array([-3.0, 0.0]), 5.0, 20.0, 4.0, margin_m=16.0)


def field_solver_for(strategy: Any, params: CommonParams, obstacles: Obstacles | None) -> ProcessPoolExecutor | None:
    """A one-worker process pool (warming up) handed to ``strategy.set_field_solver`` when the strategy
    will solve an urban field (``plume_model = "urban"`` among known buildings); None otherwise. The
    caller shuts it down (``shutdown(wait=False, cancel_futures=True)``) after the mission."""
    hook = getattr(strategy, "set_field_solver", None)
    if hook is None or obstacles is None or not len(obstacles) or getattr(params, "plume_model", "") != "urban":
        return None
    pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=numba_cache.configure)
    pool.submit(warm_up)
    hook(pool)
    return pool


def _ready() -> bool:
    return True


async def warmed(pool: ProcessPoolExecutor, limit_s: float, say: Callable[[str], None]) -> bool:
    """Wait (at most ``limit_s`` wall seconds) until the worker has finished its warm-up: a no-op queued behind
    it on the one worker comes back after it. Before take-off, so that the solve in flight is the 0.5 s of the
    field alone and not a cold start's imports and compilation (which, on a loaded machine at a SITL speed-up,
    outran the strategy's cap on the hover: ``ste_city.FIELD_SOLVE_LIMIT_S`` vehicle seconds). False (said) if
    the worker is not ready by then; the mission goes on and the cap still holds."""
    try:
        await asyncio.wait_for(asyncio.wrap_future(pool.submit(_ready)), limit_s)
        return True
    except (TimeoutError, OSError, RuntimeError) as e:
        say(f"the urban field's worker is not ready after {limit_s:g} s ({type(e).__name__}): flying on, the solve "
            "may run past its cap")  # fmt: skip
        return False
