"""Recording cost: the same work with and without the Rerun recorder, the CPU-time ratio in the same run.

Two figures (the recorder must cost at most 10 % of either):

1. **In-process runner**: ``run_trial`` (open-field, surge-cast, evaluation seeds) with
   ``recorder=TrialRecorder(...)`` and without, alternated, ``--repeats`` times each. The figure:
   within each recorded trial, the CPU time of the recorder's own calls (on the trial's thread)
   plus rerun's threads (it encodes and writes on its own), over the CPU time of the rest of the
   trial. Measured in the same trial, it is not disturbed by other load; the paired trials' CPU
   ratio is printed too, with its spread (it swings by tens of percent on a shared machine). The
   recorder must not change the trial: the script checks the results match.
2. **windseek demo**: ``windseek demo`` with and without ``--no-rrd`` (same scenario, strategy and
   seed), alternated. The demo is paced (``--speed``), so its wall time hardly moves; what the
   recording costs is CPU: the CPU time of the demo and its three processes (``RUSAGE_CHILDREN``
   of this script around each demo), which on a shared machine is what slows everything else.

CPU times are less disturbed by other load than wall times, but a busy machine still spreads them
by several percent: the figure is the ratio of the sums, with the spread of the per-pair ratios.

    python benchmarks/recording_cost.py                      # both, 2 seeds x 2 repeats, 2 demo pairs
    python benchmarks/recording_cost.py --skip-demo --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mission.runners.inprocess import run_trial  # noqa: E402
from recording.trial import TrialRecorder  # noqa: E402

KEYS = ("success", "declared_ned", "error_m", "time_s", "path_m", "verifications")


class TimedTrialRecorder(TrialRecorder):
    """A :class:`TrialRecorder` that counts its own CPU time on the trial's thread (the simulation
    hook, the tick, attaching and finishing); rerun's own threads are counted by the caller."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self.cpu_s = 0.0

    def _timed(self, fn, *args):  # type: ignore[no-untyped-def]
        t0 = time.thread_time()
        try:
            return fn(*args)
        finally:
            self.cpu_s += time.thread_time() - t0

    def attach(self, sim, vehicle, strategy, params=None) -> None:  # type: ignore[no-untyped-def]
        n = len(sim.step_hooks)
        self._timed(super().attach, sim, vehicle, strategy, params)
        hook = sim.step_hooks[n]  # record_simulation's
        sim.step_hooks[n] = lambda s: self._timed(hook, s)

    def _tick(self, t: float) -> None:
        self._timed(super()._tick, t)

    def finish(self, result) -> None:  # type: ignore[no-untyped-def]
        self._timed(super().finish, result)


def trial_cost(seeds: list[int], repeats: int, out: Path) -> dict:
    """Paired trials with and without the recorder, and the recorder's own share of the recorded ones."""
    run_trial("open-field", "surge-cast", seed=seeds[0], time_limit_s=5.0)  # numba kernels compiled, caches warm
    runs: dict[bool, list[float]] = {False: [], True: []}
    ratios, own, base = [], 0.0, 0.0
    for r in range(repeats):
        for seed in seeds:
            pair = {}
            for rec in ((False, True) if r % 2 == 0 else (True, False)):
                timed = TimedTrialRecorder(out / f"trial-{seed}.rrd") if rec else None
                c0, m0 = time.process_time(), time.thread_time()
                res = run_trial("open-field", "surge-cast", seed=seed, recorder=timed)
                cpu, main_cpu = time.process_time() - c0, time.thread_time() - m0
                runs[rec].append(cpu)
                pair[rec] = (cpu, res)
                if timed is not None:  # the recorder's calls + rerun's threads, against the rest of the trial
                    mine = timed.cpu_s + (cpu - main_cpu)
                    own += mine
                    base += cpu - mine
            if any(getattr(pair[True][1], k) != getattr(pair[False][1], k) for k in KEYS):
                raise SystemExit(f"seed {seed}: the recorder changed the trial's result")
            ratios.append(pair[True][0] / pair[False][0])
            print(f"  seed {seed}: {pair[False][0]:6.2f} s CPU without, {pair[True][0]:6.2f} s with "
                  f"(x{ratios[-1]:.3f}), {pair[True][1].time_s:.1f} s of flight", flush=True)  # fmt: skip
    return {"own_ratio": 1.0 + own / base, "own_s": own, "cpu_ratio": sum(runs[True]) / sum(runs[False]),
            "pair_ratio_min": min(ratios), "pair_ratio_max": max(ratios), "trials": len(ratios)}  # fmt: skip


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def demo_cost(pairs: int, seed: int, speed: float, out: Path) -> dict:
    runs: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
    ratios = []
    for p in range(pairs):
        pair = {}
        for rec in ((False, True) if p % 2 == 0 else (True, False)):
            cmd = [sys.executable, "-m", "windseek.cli", "demo", "--seed", str(seed), "--speed", f"{speed:g}",
                   "--logs", str(out / f"demo-{p}-{int(rec)}"), "--json", *([] if rec else ["--no-rrd"])]  # fmt: skip
            c0, w0 = _children_cpu(), time.perf_counter()
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=dict(os.environ))
            cpu, wall = _children_cpu() - c0, time.perf_counter() - w0
            if r.returncode not in (0, 1):
                raise SystemExit(f"windseek demo failed ({r.returncode}):\n{r.stderr[-2000:]}")
            s = json.loads(r.stdout.strip().splitlines()[-1])
            runs[rec].append((cpu, wall))
            pair[rec] = cpu
            print(f"  demo {'with' if rec else 'without'} recording: {cpu:6.1f} s CPU (4 processes), {wall:5.1f} s "
                  f"wall, {s['mission_time_s']} s arm to disarm", flush=True)  # fmt: skip
        ratios.append(pair[True] / pair[False])
    cpu = {k: sum(c for c, _ in v) for k, v in runs.items()}
    wall = {k: sum(w for _, w in v) for k, v in runs.items()}
    return {"cpu_ratio": cpu[True] / cpu[False], "wall_ratio": wall[True] / wall[False],
            "pair_ratio_min": min(ratios), "pair_ratio_max": max(ratios), "pairs": pairs}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1000,1001", help="evaluation seeds of the in-process trials")
    ap.add_argument("--repeats", type=int, default=2, help="repeats of each in-process pair")
    ap.add_argument("--demo-pairs", type=int, default=2, help="demo runs with and without recording")
    ap.add_argument("--demo-seed", type=int, default=1000)
    ap.add_argument("--speed", type=float, default=5.0, help="demo speed factor")
    ap.add_argument("--skip-demo", action="store_true")
    a = ap.parse_args()
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as d:
        out = Path(d)
        print(f"in-process runner (load average {load:.1f} on {os.cpu_count()} cores):", flush=True)
        t = trial_cost([int(s) for s in a.seeds.split(",")], a.repeats, out)
        print(f"in-process: the recorder's own CPU (its calls + rerun's threads) x{t['own_ratio']:.3f} of the rest "
              f"of the trials ({t['own_s']:.2f} s); paired trials x{t['cpu_ratio']:.3f} CPU (pairs "
              f"x{t['pair_ratio_min']:.3f} .. x{t['pair_ratio_max']:.3f}, {t['trials']} pairs)")  # fmt: skip
        if not a.skip_demo:
            print("windseek demo:", flush=True)
            dm = demo_cost(a.demo_pairs, a.demo_seed, a.speed, out)
            print(f"demo: recording costs x{dm['cpu_ratio']:.3f} CPU (pairs x{dm['pair_ratio_min']:.3f} .. "
                  f"x{dm['pair_ratio_max']:.3f}), wall x{dm['wall_ratio']:.3f} (paced at speed {a.speed:g})")  # fmt: skip
    print(f"load average now {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
