"""Campaign throughput: search missions per hour through ``windseek campaign``'s Dask executor at 1 and
2 workers, and where one mission's CPU time goes.

Missions: open-field / surge-cast / estimated wind, in-process (lockstep), seeds 3000.. (the
missions of ``campaigns/throughput.toml``; not used for tuning or evaluation tables). Each worker
count flies the same missions on a fresh local cluster (single-threaded worker processes); the
kernels are warmed on every worker first (not timed), the clock runs from the first submission to
the last result. Printed: missions per hour (wall), scaling efficiency (rate at 2 workers / twice
the rate at 1), the mean CPU seconds per mission in the workers and the capacity they imply
(workers x 3600 / CPU s: the rate on an otherwise idle machine if the CPU cost held; load inflates
CPU time too, so under load it is a lower bound), each worker's peak resident memory, and the load
average before and after (the machine is shared). Peer (``--loop N``): the first N missions in a
plain loop in this process (no Dask); the executor's per-mission overhead is the difference in wall
time (a row's ``cpu_s`` is the worker thread's CPU time, without scheduling or transfer).
Each row is printed, and the JSON written, as soon as it is measured.

The breakdown flies ``--breakdown`` missions in this process with every part timed (CPU time,
exclusive of the parts it calls): setup (scenario, turbulence synthesis), plume warm-up,
physics + autopilot (the fused loop), plume (puffs, concentration, chemical sensor), sensors,
estimator (UKF), AHRS model and estimator feed, strategy, mission loop and scoring (the rest). The
timers are removed before the rates are measured.

    python benchmarks/campaign_throughput.py [--missions 60] [--workers 1,2] [--breakdown 10] [--loop 0]
                                             [--json out.json]
    # benchmarks/README.md's figures (about 10 min at load 6-9):
    python benchmarks/campaign_throughput.py --missions 30 --workers 1,2 --breakdown 5 --loop 8
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()

from mission.campaign.grid import expand
from mission.campaign.spec import parse_campaign
from mission.campaign.task import Task

#: Issue 21's goal: search missions per hour on this 2-core machine.
GOAL_PER_HOUR = 2000
SPEC = Path(__file__).resolve().parent.parent / "campaigns" / "throughput.toml"


def _tasks(n: int, seed0: int) -> list[Task]:
    import tomllib

    data = tomllib.loads(SPEC.read_text())
    data["campaign"]["seeds"] = {"start": seed0, "count": n}
    return expand(parse_campaign(data, SPEC))


def _load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


# ------------------------------------------------------------------ the breakdown
class _Timers:
    """Exclusive CPU time per part: a wrapped call's time minus the wrapped calls it makes."""

    def __init__(self) -> None:
        self.total: dict[str, float] = defaultdict(float)
        self.stack: list[list[float]] = []  # [start, children]
        self.originals: list[tuple[Any, str, Any]] = []  # (class, name, own attribute or None)

    def wrap(self, owner: Any, name: str, part: str) -> None:
        fn = getattr(owner, name)
        self.originals.append((owner, name, vars(owner).get(name)))  # None: inherited
        clock = time.process_time

        @functools.wraps(fn)
        def timed(*a: Any, **kw: Any) -> Any:
            self.stack.append([clock(), 0.0])
            try:
                return fn(*a, **kw)
            finally:
                t0, children = self.stack.pop()
                dt = clock() - t0
                self.total[part] += dt - children
                if self.stack:
                    self.stack[-1][1] += dt

        setattr(owner, name, timed)

    def restore(self) -> None:
        """Put the original methods back (the rates measured after the breakdown run untimed)."""
        for owner, name, fn in reversed(self.originals):
            if fn is None:
                delattr(owner, name)  # the base class's method shows through again
            else:
                setattr(owner, name, fn)
        self.originals.clear()


PARTS = [
    ("setup: scenario, turbulence synthesis, vehicle", [("sitl.simulation", "Simulation", "__init__")]),
    ("plume warm-up (120 s of puffs before t = 0)", [("sitl.world.plume.part", "PlumePart", "__init__")]),
    ("physics + autopilot (fused loop, 500 Hz)", [("sitl.world.world", "World", "step")]),
    ("plume: puff update, concentration, chem sensor", [("sitl.world.plume.part", "PlumePart", "on_slow_tick")]),
    ("sensors: IMU, ESC, GNSS, baro, mag", [("sitl.world.world", "World", "_imu_batch"),
                                            ("sitl.world.world", "World", "_slow_tick")]),
    ("estimator (UKF predict + updates)", [("estimator.ukf", "WindEstimator", m) for m in
                                           ("imu", "imu_batch", "gnss_velocity", "set_rotor_speeds", "set_attitude")]),
    ("AHRS model, estimator feed, direction filter", [("mission.wind_source", "EstimatedWind", "update")]),
    ("strategy (surge-cast)", [("mission.strategies.surge_cast", "SurgeCast", "update")]),
]


def breakdown(n: int, seed0: int) -> tuple[list[tuple[str, float]], float]:
    """[(part, CPU s per mission)], total CPU s per mission, over ``n`` missions flown here."""
    import importlib

    from mission.campaign.worker import run_task, warm_up

    warm_up()
    timers = _Timers()
    for part, targets in PARTS:
        for mod, cls, meth in targets:
            timers.wrap(getattr(importlib.import_module(mod), cls), meth, part)
    tasks = _tasks(n, seed0)
    c0 = time.process_time()
    try:
        for t in tasks:
            run_task(t)
    finally:
        timers.restore()
    total = (time.process_time() - c0) / n
    parts = [(p, timers.total[p] / n) for p, _ in PARTS]
    parts.append(("mission loop, safety, scoring, the rest", total - sum(v for _, v in parts)))
    return parts, total


# ------------------------------------------------------------------ the rates
def dask_rate(tasks: list[Task], workers: int) -> dict[str, Any]:
    from mission.campaign.execute import connect, execute
    from mission.campaign.store import ResultStore, read_results

    load0 = _load()
    client, cluster = connect(None, workers)
    try:
        with tempfile.TemporaryDirectory() as d:
            store = ResultStore(Path(d) / "r", "throughput").open()
            rep = execute(client, tasks, store, f"{workers} workers", progress=False)
            store.close()
            table = read_results(Path(d) / "r")
            cpu, rss = table.column("cpu_s").to_pylist(), table.column("rss_mb").to_pylist()
    finally:
        client.close(timeout=10)
        cluster.close(timeout=20)
    mean_cpu = sum(cpu) / len(cpu)
    return {"workers": workers, "missions": rep.done, "errors": rep.errors, "wall_s": rep.wall_s,
            "per_hour": rep.per_hour, "cpu_s_mean": mean_cpu, "capacity_per_hour": workers * 3600.0 / mean_cpu,
            "worker_peak_rss_mb": max(rss), "load_before": load0, "load_after": _load()}  # fmt: skip


def loop_rate(tasks: list[Task]) -> dict[str, Any]:
    from mission.campaign.worker import run_task, warm_up

    warm_up()
    load0 = _load()
    w0, c0 = time.perf_counter(), time.process_time()
    for t in tasks:
        run_task(t)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return {"workers": "loop", "missions": len(tasks), "wall_s": wall, "per_hour": 3600 * len(tasks) / wall,
            "cpu_s_mean": cpu / len(tasks), "capacity_per_hour": 3600 * len(tasks) / cpu, "load_before": load0,
            "load_after": _load()}  # fmt: skip


def _print_rate(r: dict[str, Any], one: dict[str, Any] | None) -> None:
    """One row of the table, printed as soon as it is measured (a run cut short keeps what it has)."""
    scaled = one is not None and isinstance(r["workers"], int)
    r["efficiency"] = r["per_hour"] / (r["workers"] * one["per_hour"]) if scaled and one else float("nan")
    rss = f" | {r['worker_peak_rss_mb']:.0f} MB" if "worker_peak_rss_mb" in r else " | -"
    print(f"{r['workers']} | {r['missions']} | {r['wall_s']:.0f} | {r['per_hour']:,.0f} | {r['cpu_s_mean']:.2f} | "
          f"{r['capacity_per_hour']:,.0f} | {r['efficiency']:.2f} | {r['load_before']} -> {r['load_after']}{rss}",
          flush=True)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", type=int, default=60, help="missions per worker count (default 60)")
    ap.add_argument("--seed", type=int, default=3000)
    ap.add_argument("--workers", default="1,2", help="worker counts, comma-separated (default 1,2)")
    ap.add_argument("--loop", type=int, default=0, help="also fly this many missions in a plain loop (the peer)")
    ap.add_argument("--breakdown", type=int, default=10, help="missions flown with timed parts (0: none)")
    ap.add_argument("--json", default=None, help="write the figures to this JSON file (after every measurement)")
    args = ap.parse_args()
    out: dict[str, Any] = {"date": time.strftime("%Y-%m-%d"), "cores": os.cpu_count(), "rates": []}

    def save() -> None:
        if args.json:
            Path(args.json).write_text(json.dumps(out, indent=1))

    if args.breakdown:
        parts, total = breakdown(args.breakdown, args.seed)
        out["breakdown"] = {"missions": args.breakdown, "cpu_s_per_mission": total, "parts": dict(parts)}
        print(f"CPU per mission, {args.breakdown} missions in one process (load {_load()}): {total:.2f} s")
        for p, v in parts:
            print(f"  {p:48s} {v:6.3f} s  {100 * v / total:5.1f} %", flush=True)
        save()
    tasks = _tasks(args.missions, args.seed)
    print("workers | missions | wall s | missions/h | CPU s/mission | capacity/h (idle) | efficiency | "
          "load before/after | worker peak RSS", flush=True)
    one = None
    runs: list[Any] = [lambda: loop_rate(tasks[: args.loop])] if args.loop else []
    runs += [functools.partial(dask_rate, tasks, int(w)) for w in args.workers.split(",") if w]
    for run in runs:
        r = run()
        one = r if r["workers"] == 1 else one
        _print_rate(r, one)
        out["rates"].append(r)
        save()
    cores = os.cpu_count() or 1
    print(f"goal {GOAL_PER_HOUR:,} missions/h on {cores} cores needs <= {cores * 3600 / GOAL_PER_HOUR:.2f} CPU s "
          "per mission (idle machine, perfect scaling)")


if __name__ == "__main__":
    main()
    sys.exit(0)
