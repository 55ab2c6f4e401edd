"""The worker side of a campaign: one mission -> one results row, and the once-per-worker set-up.

Importing this module points the JIT compiler at the project's kernel cache
(:func:`toolchain.numba_cache.configure`) before any kernel module is imported, so it is safe as a
Dask preload (``dask worker ... --preload mission.campaign.worker``): :func:`dask_setup` then
loads and runs every kernel once (:func:`warm_up`) before the worker takes tasks. A client also
registers :class:`WarmUpPlugin`, which does the same on every worker of any cluster, including
workers that join later; on a worker already warm it costs nothing.
"""

from __future__ import annotations

import functools
import os
import resource
import subprocess
import sys
import threading
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from mission.campaign.rows import ok_row, windseek_version
from mission.campaign.task import Task
from toolchain import numba_cache

numba_cache.configure()
_warm = False
_warm_lock = threading.Lock()


def run_task(task: Task) -> dict[str, Any]:
    """Fly one mission in lockstep (:func:`mission.runners.inprocess.run_trial`) and return its row."""
    from mission.runners.inprocess import run_trial
    from mission.strategies.params import params_from_table
    from sitl.scenario import parse_scenario

    cpu0, wall0 = time.thread_time(), time.perf_counter()
    sc = parse_scenario(task.scenario_table, task.scenario)
    params = params_from_table(task.strategy, task.strategy_table)
    res = run_trial(sc, task.strategy, task.wind, seed=task.seed, params=params, time_limit_s=task.time_limit_s,
                    geofence_m=task.geofence_m)  # fmt: skip
    assert sc.plume is not None  # checked when the grid was expanded
    cost = {"cpu_s": time.thread_time() - cpu0, "wall_s": time.perf_counter() - wall0, **provenance()}
    return ok_row(task, res, sc.plume.plume.sources[0].position_ned, sc.start.position_ned, asdict(params), cost)


def provenance() -> dict[str, Any]:
    """Where and with what a mission ran: worker, peak memory [MB], versions."""
    return {"worker": _worker_name(), "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "windseek_version": windseek_version(), "code_commit": code_commit()}  # fmt: skip


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except ValueError:  # not inside a Dask worker
        return f"local:{os.getpid()}"


@functools.cache
def code_commit() -> str:
    """The git commit of the code this process runs (``+dirty`` with uncommitted changes), or ``""``."""
    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()  # fmt: skip
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return ""
    return head + ("+dirty" if dirty else "")


def warm_up() -> float:
    """Load (or compile, the first time on a machine) every kernel a mission uses by flying a few
    seconds of a small search; once per process. Returns the seconds it took (0 when already warm)."""
    global _warm
    with _warm_lock:
        if _warm:
            return 0.0
        t0 = time.perf_counter()
        from mission.runners.inprocess import run_trial
        from sitl.scenario import parse_scenario, scenario_table

        table = scenario_table("open-field")[0]
        table["plume"]["warmup_s"] = 5.0
        run_trial(parse_scenario(table, "warm-up"), "surge-cast", "estimated", seed=0, time_limit_s=4.0)
        code_commit()
        _warm = True
        return time.perf_counter() - t0


class WarmUpPlugin(WorkerPlugin):
    """Runs :func:`warm_up` on each worker once, off the worker's event loop (it keeps its heartbeats)."""

    name = "windseek-warm-up"

    async def setup(self, worker: Any) -> None:
        import asyncio

        await asyncio.get_running_loop().run_in_executor(None, warm_up)


def dask_setup(worker: Any) -> None:
    """``--preload mission.campaign.worker``: warm the kernels before the worker takes tasks."""
    seconds = warm_up()
    print(f"windseek campaign worker {getattr(worker, 'address', '')}: kernels ready in {seconds:.1f} s",
          file=sys.stderr)  # fmt: skip
