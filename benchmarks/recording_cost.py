"""Recording cost: the Rerun recorder's CPU time against the rest of the run's, in the same run.

The recorder must cost at most 10 % of the in-process runner and of the demo. Both recorders
measure what recording costs them while they run (``recording.stream.CpuMeter``) and store it in
the recording (property ``recording_cost``): the CPU time of the recorder's calls on the run's
thread, of rerun's own threads (encoding, writing), and of the whole process since the recorder
started. The figure is 1 + recording / (process - recording). Measured inside each run, it is not
disturbed by other load on a shared machine the way a comparison of two runs is (CPU times of two
identical trials differ by tens of percent here), and a demo flies a different mission each time
(three processes, real-time pacing), so two demos cannot be compared at all.

1. **In-process runner**: ``run_trial`` (open-field, surge-cast, evaluation seeds) with
   ``recorder=TrialRecorder(...)``. The same trials without a recorder are run too, alternated:
   their CPU ratio is printed (noisy), and the script checks the recorder changed no result.
2. **windseek demo**: recorded demos; the SITL records. The demo's own part, adding its summary to
   the recording after the run (``recording.finalize``, timed again on a copy), is added to the
   recording's share; the estimator and the mission do not record (their CPU is left out of the
   denominator: the figure is against the SITL alone).

    python benchmarks/recording_cost.py                      # 2 seeds x 2 repeats, 3 demos
    python benchmarks/recording_cost.py --skip-demo --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mission.runners.inprocess import run_trial  # noqa: E402
from recording.finalize import add_demo_result  # noqa: E402
from recording.read import RrdLog  # noqa: E402
from recording.trial import TrialRecorder  # noqa: E402

KEYS = ("success", "declared_ned", "error_m", "time_s", "path_m", "verifications")


def own_share(path: Path, extra_cpu_s: float = 0.0) -> tuple[float, float, float]:
    """From a recording's ``recording_cost`` property: (recorder + rerun's threads [+ extra] CPU s,
    the rest of the process's CPU s since the recorder started, simulated s)."""
    log = RrdLog(path)
    cost = {k: float(log.property_value("recording_cost", k)) for k in
            ("recorder_cpu_s", "rerun_cpu_s", "process_cpu_s", "sim_s")}  # fmt: skip
    own = cost["recorder_cpu_s"] + cost["rerun_cpu_s"]
    return own + extra_cpu_s, cost["process_cpu_s"] - own, cost["sim_s"]


def trial_cost(seeds: list[int], repeats: int, out: Path, strategy: str = "surge-cast") -> dict:
    """Paired trials with and without the recorder; the recorder's own share of the recorded ones and
    the recordings' sizes."""
    run_trial("open-field", strategy, seed=seeds[0], time_limit_s=5.0)  # numba kernels compiled, caches warm
    # and a recorded one: rerun's and the recorder's one-time imports and set-up are not a trial's cost
    run_trial("open-field", strategy, seed=seeds[0], time_limit_s=5.0, recorder=TrialRecorder(out / "warm.rrd"))
    runs: dict[bool, list[float]] = {False: [], True: []}
    ratios, own, rest, sizes = [], 0.0, 0.0, []
    for r in range(repeats):
        for seed in seeds:
            pair = {}
            for rec in ((False, True) if r % 2 == 0 else (True, False)):
                path = out / f"trial-{seed}.rrd"
                c0 = time.process_time()
                res = run_trial("open-field", strategy, seed=seed, recorder=TrialRecorder(path) if rec else None)
                cpu = time.process_time() - c0
                runs[rec].append(cpu)
                pair[rec] = (cpu, res)
                if rec:
                    o, rst, _ = own_share(path)
                    own, rest = own + o, rest + rst
                    sizes.append(path.stat().st_size)
            if any(getattr(pair[True][1], k) != getattr(pair[False][1], k) for k in KEYS):
                raise SystemExit(f"seed {seed}: the recorder changed the trial's result")
            ratios.append(pair[True][0] / pair[False][0])
            print(f"  seed {seed}: {pair[False][0]:6.2f} s CPU without, {pair[True][0]:6.2f} s with "
                  f"(x{ratios[-1]:.3f}), {pair[True][1].time_s:.1f} s of flight", flush=True)  # fmt: skip
    return {"own_ratio": 1.0 + own / rest, "own_s": own, "cpu_ratio": sum(runs[True]) / sum(runs[False]),
            "pair_ratio_min": min(ratios), "pair_ratio_max": max(ratios),
            "pair_ratio_median": statistics.median(ratios), "trials": len(ratios),
            "bytes_min": min(sizes), "bytes_max": max(sizes)}  # fmt: skip


def demo_cost(runs: int, seed: int, speed: float, out: Path) -> dict:
    """Recorded demos: the SITL's recording cost (its ``recording_cost`` property: the recorder's
    calls and rerun's threads against the rest of the SITL's CPU while it recorded) plus the demo's
    own part, adding its summary to the recording (timed again on a copy)."""
    own, rest, sim = 0.0, 0.0, 0.0
    for k in range(runs):
        cmd = [sys.executable, "-m", "windseek.cli", "demo", "--seed", str(seed), "--speed", f"{speed:g}",
               "--logs", str(out / f"demo-{k}"), "--json"]  # fmt: skip
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        if r.returncode not in (0, 1):
            raise SystemExit(f"windseek demo failed ({r.returncode}):\n{r.stderr[-2000:]}")
        s = json.loads(r.stdout.strip().splitlines()[-1])
        rrd = Path(s["files"]["rrd"])
        copy = rrd.with_name("copy.rrd")
        copy.write_bytes(rrd.read_bytes())
        c0 = time.process_time()
        add_demo_result(copy, s)
        fin = time.process_time() - c0
        o, rst, sim_s = own_share(rrd, fin)
        own, rest, sim = own + o, rest + rst, sim + sim_s
        print(f"  demo {k + 1}: SITL {rst:5.2f} s CPU while recording {sim_s:5.1f} s simulated; recording {o:5.3f} s "
              f"(x{1 + o / rst:.3f}, the summary added in {fin:.3f} s), {rrd.stat().st_size / 1e6:.1f} MB", flush=True)
    return {"own_ratio": 1.0 + own / rest, "own_s": own, "rest_s": rest, "sim_s": sim, "runs": runs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1000,1001", help="evaluation seeds of the in-process trials")
    ap.add_argument("--repeats", type=int, default=2, help="repeats of each in-process pair")
    ap.add_argument("--strategy", default="surge-cast", help="strategy of the in-process trials (open-field)")
    ap.add_argument("--demo-runs", type=int, default=3, help="recorded demo runs")
    ap.add_argument("--demo-seed", type=int, default=1000)
    ap.add_argument("--speed", type=float, default=5.0, help="demo speed factor")
    ap.add_argument("--skip-demo", action="store_true")
    ap.add_argument("--skip-trials", action="store_true")
    a = ap.parse_args()
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as d:
        out = Path(d)
        print(f"load average {load:.1f} on {os.cpu_count()} cores", flush=True)
        if not a.skip_trials:
            print(f"in-process runner ({a.strategy}):", flush=True)
            t = trial_cost([int(s) for s in a.seeds.split(",")], a.repeats, out, a.strategy)
            print(f"in-process: the recorder's own CPU (its calls + rerun's threads) x{t['own_ratio']:.3f} of the rest "
                  f"of the trials ({t['own_s']:.2f} s); paired trials x{t['cpu_ratio']:.3f} CPU (median pair "
                  f"x{t['pair_ratio_median']:.3f}, pairs x{t['pair_ratio_min']:.3f} .. x{t['pair_ratio_max']:.3f}, "
                  f"{t['trials']} pairs); recordings {t['bytes_min'] / 1e3:.0f}-{t['bytes_max'] / 1e3:.0f} kB")
        if not a.skip_demo:
            print("windseek demo:", flush=True)
            dm = demo_cost(a.demo_runs, a.demo_seed, a.speed, out)
            print(f"demo: recording costs the SITL (and the demo adding its summary) x{dm['own_ratio']:.3f} CPU "
                  f"({dm['own_s']:.2f} s over {dm['rest_s']:.1f} s, {dm['sim_s']:.0f} s simulated, {dm['runs']} runs, "
                  f"speed {a.speed:g})")  # fmt: skip
    print(f"load average now {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
