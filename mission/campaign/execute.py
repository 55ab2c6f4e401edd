"""Running a campaign's missions on Dask (``dask.distributed``): the thin adapter between the
missions (:mod:`mission.campaign.worker`) and the results (:mod:`mission.campaign.store`).

- :func:`connect`: a local cluster (one single-threaded worker process per core) or an existing
  scheduler (``tcp://HOST:8786`` or a scheduler file), reached within a bounded time.
- :func:`execute`: every mission is one task (Dask key ``windseek-<mission key>``), submitted in a
  bounded window (a few per worker thread, so a 100,000-mission campaign does not sit in the
  scheduler's memory). A task that raises is retried once by Dask; a task whose worker dies is
  rescheduled on another worker by the scheduler (up to its ``allowed-failures``); a task that still
  fails becomes an ``error`` row and the campaign goes on. Rows are appended to the store as they
  arrive. Progress: missions done, rate per hour and ETA (rich on a terminal; otherwise a line
  every 30 s).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mission.campaign.rows import error_row
from mission.campaign.spec import CampaignError
from mission.campaign.store import ResultStore
from mission.campaign.task import Task

#: Seconds to reach a scheduler, and to wait for its first worker.
CONNECT_TIMEOUT_S = 10.0
WORKER_WAIT_S = 60.0
#: Missions in flight per worker thread (enough to keep every worker busy between round trips).
PER_THREAD = 4


def cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def connect(scheduler: str | None, workers: int | None = None) -> tuple[Any, Any]:
    """(client, local cluster or None). ``scheduler``: None (start a local cluster of ``workers``
    single-threaded processes, default one per core), an address, or a scheduler JSON file."""
    from distributed import Client, LocalCluster

    if scheduler is None:
        n = workers or cores()
        if n < 1:
            raise CampaignError(f"--workers {n}: must be >= 1")
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)  # fmt: skip
        return Client(cluster), cluster
    is_file = scheduler.endswith(".json") or Path(scheduler).is_file()
    if is_file and not Path(scheduler).is_file():
        raise CampaignError(f"--scheduler {scheduler}: no such scheduler file")
    if not is_file and "://" not in scheduler and ":" not in scheduler:
        raise CampaignError(f"--scheduler {scheduler!r}: expected tcp://HOST:PORT (or a scheduler .json file)")
    try:
        kw: dict[str, Any] = {"scheduler_file": scheduler} if is_file else {"address": scheduler}
        client = Client(timeout=CONNECT_TIMEOUT_S, **kw)
    except (OSError, TimeoutError, ValueError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise CampaignError(f"cannot reach the Dask scheduler {scheduler} within {CONNECT_TIMEOUT_S:g} s "
                            f"({reason[:160]})") from None  # fmt: skip
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except TimeoutError:
        client.close()
        raise CampaignError(f"the Dask scheduler {scheduler} has no worker (waited {WORKER_WAIT_S:g} s)") from None
    return client, None


@dataclass
class RunReport:
    """What one run did: missions finished and errors this run, wall seconds, the rate [missions/h]."""

    done: int = 0
    errors: int = 0
    lost: int = 0
    wall_s: float = 0.0
    error_lines: list[str] = field(default_factory=list)

    @property
    def per_hour(self) -> float:
        return 3600.0 * self.done / self.wall_s if self.wall_s > 0 else 0.0


def execute(client: Any, todo: list[Task], store: ResultStore, label: str, progress: bool = True,
            retries: int = 1, warm: bool = True) -> RunReport:
    """Fly ``todo`` on the client's cluster, appending each row to ``store`` as it arrives."""
    from distributed import as_completed

    from mission.campaign.worker import WarmUpPlugin, run_task

    if warm:
        client.register_plugin(WarmUpPlugin())
    report = RunReport()
    pending: Iterator[Task] = iter(todo)
    in_flight: dict[str, Task] = {}
    ac = as_completed()
    window = _Window(client)

    def submit() -> None:
        while len(in_flight) < window.size():
            task = next(pending, None)
            if task is None:
                return
            fut = client.submit(run_task, task, key=f"windseek-{task.key}", retries=retries, pure=False)
            in_flight[fut.key] = task
            ac.add(fut)

    t0 = time.perf_counter()
    with _Progress(label, len(todo), progress) as bar:
        submit()
        for fut in ac:
            task = in_flight.pop(fut.key)
            if fut.status == "finished":
                row = fut.result()
            elif fut.status == "cancelled":  # the scheduler forgot it (lost connection): not the mission's fault
                report.lost += 1
                fut.release()
                continue
            else:
                exc = fut.exception()
                line = f"{type(exc).__name__}: {exc}".splitlines()[0][:300]
                row = error_row(task, line)
                report.errors += 1
                report.error_lines.append(f"{task.scenario} / {task.strategy} / {task.wind} / seed {task.seed}: {line}")
            fut.release()
            store.add(row)
            report.done += 1
            bar.advance(report.errors)
            submit()
    report.wall_s = time.perf_counter() - t0
    store.flush()
    return report


class _Window:
    """Missions to keep in flight: PER_THREAD per worker thread (re-read every 30 s: workers come and go)."""

    def __init__(self, client: Any) -> None:
        self.client, self._size, self._t = client, 0, -1e9

    def size(self) -> int:
        if time.monotonic() - self._t > 30.0:
            threads = sum(self.client.nthreads().values())
            self._size, self._t = max(8, PER_THREAD * threads), time.monotonic()
        return self._size


class _Progress:
    """Missions done / total, rate per hour, ETA: a rich bar on a terminal, else a line every ``every_s``
    seconds (and at the end), for logs of batch jobs."""

    def __init__(self, label: str, total: int, enabled: bool, out: Callable[[str], None] | None = None,
                 every_s: float = 30.0) -> None:
        self.label, self.total, self.enabled, self.every_s = label, total, enabled, every_s
        self.out = out or (lambda s: print(s, file=sys.stderr, flush=True))
        self.done, self.t0, self.t_line = 0, time.monotonic(), time.monotonic()
        self.bar: Any = None
        self.tty = sys.stderr.isatty()

    def __enter__(self) -> _Progress:
        if self.enabled and self.tty:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self.bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("{task.fields[rate]}"), TextColumn("ETA"), TimeRemainingColumn(),
                                TextColumn("{task.fields[errors]}"), console=Console(stderr=True))  # fmt: skip
            self.bar.start()
            self.task = self.bar.add_task(self.label, total=self.total, rate="", errors="")
        return self

    def rate(self) -> float:
        dt = time.monotonic() - self.t0
        return 3600.0 * self.done / dt if dt > 0 else 0.0

    def advance(self, errors: int) -> None:
        self.done += 1
        rate = self.rate()
        if self.bar is not None:
            self.bar.update(self.task, advance=1, rate=f"{rate:,.0f}/h", errors=f"{errors} errors" if errors else "")
        elif self.enabled and (time.monotonic() - self.t_line >= self.every_s or self.done == self.total):
            self.t_line = time.monotonic()
            eta = (self.total - self.done) / rate * 3600.0 if rate > 0 else float("nan")
            self.out(f"{self.label}: {self.done}/{self.total} missions, {rate:,.0f}/h, ETA {_hms(eta)}, "
                     f"{errors} errors")  # fmt: skip

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            with contextlib.suppress(Exception):
                self.bar.stop()


def _hms(s: float) -> str:
    if s != s:
        return "-"
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"
