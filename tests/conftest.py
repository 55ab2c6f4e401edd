"""Test-suite set-up: one BLAS thread and numba's kernel cache (both before numpy and any kernel module
are imported), the markers."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the windseek command sets it (windseek/cli.py)

from toolchain import numba_cache  # noqa: E402

numba_cache.configure()


def pytest_sessionstart(session: object) -> None:
    """With several test processes (pytest-xdist), the controller compiles the kernels once before the workers
    start (or loads them from numba's cache): two workers compiling one kernel at once would each stall for
    tens of seconds, and a test whose simulation thread stalls misses its wall-clock waits."""
    import os

    config = getattr(session, "config", None)
    if os.environ.get("PYTEST_XDIST_WORKER") or not getattr(getattr(config, "option", None), "numprocesses", None):
        return
    from mission.runners.inprocess import run_trial
    from sitl.scenario import load_scenario
    from sitl.simulation import Simulation

    for strategy in ("surge-cast", "infotaxis", "zigzag"):
        run_trial("open-field-low", strategy, "estimated", seed=1, time_limit_s=3.0)
    Simulation(load_scenario("paper-s4"), seed=1).run(0.5)
