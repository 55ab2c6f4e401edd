"""What the urban layers of a recording cost (issue 20 item 6): their static logging and the file size.

1. ``record_urban`` (buildings, the wind slice and the vertical section, logged once) on a paper-s4
   simulation: CPU on the calling thread, and process CPU through a flush (rerun's encoding and
   writing included), ``--repeats`` times.
2. Paired in-process trials (paper-s4 / surge-cast / development seed 101) with and without the
   layers (``record_urban`` replaced by a no-op), alternated: the ``.rrd`` size and the recording's
   own CPU from its ``recording_cost`` property (as ``recording_cost.py`` reads it).

    python benchmarks/urban_recording_cost.py                 # 5 repeats, 3 pairs of 120 s trials
    python benchmarks/urban_recording_cost.py --pairs 1 --time-limit 4
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mission.runners.inprocess import run_trial  # noqa: E402
from recording import sim_hook  # noqa: E402
from recording.read import RrdLog  # noqa: E402
from recording.recorder import RunRecorder  # noqa: E402
from recording.trial import TrialRecorder  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402
from sitl.simulation import Simulation  # noqa: E402

SCENARIO, STRATEGY, SEED, ALTITUDE_M = "paper-s4", "surge-cast", 101, 3.0


def static_cost(repeats: int, out: Path) -> None:
    sc = load_scenario(SCENARIO)
    sim = Simulation(sc, seed=SEED)
    assert sim.chem is not None
    for i in range(repeats):
        rec = RunRecorder(out / f"static-{i}.rrd", blueprint=False)
        rec.set_scene([np.asarray(sc.start.position_ned)[:2], sim.chem.sources_ned[0][:2]], altitude_m=5.0)
        rec.rec.flush()
        p0, t0 = time.process_time(), time.thread_time()
        sim_hook.record_urban(sim, rec, ALTITUDE_M)
        t1 = time.thread_time()
        rec.rec.flush()
        print(f"record_urban: {1e3 * (t1 - t0):.1f} ms on the calling thread, "
              f"{1e3 * (time.process_time() - p0):.1f} ms with rerun's flush", flush=True)  # fmt: skip
        rec.close()


def paired(pairs: int, time_limit_s: float, out: Path) -> None:
    real = sim_hook.record_urban
    for i in range(pairs):
        for layers in (True, False):
            sim_hook.record_urban = real if layers else (lambda *a, **k: False)
            path = out / f"trial-{i}-{int(layers)}.rrd"
            run_trial(SCENARIO, STRATEGY, seed=SEED, time_limit_s=time_limit_s, recorder=TrialRecorder(path))
            log = RrdLog(path)
            c = {k: float(log.property_value("recording_cost", k)) for k in
                 ("recorder_cpu_s", "rerun_cpu_s", "process_cpu_s")}  # fmt: skip
            own = c["recorder_cpu_s"] + c["rerun_cpu_s"]
            print(f"layers {'with' if layers else 'without':7}: {path.stat().st_size / 1e3:7.1f} kB, recording "
                  f"{own:.3f} s of {c['process_cpu_s']:.3f} s CPU -> x{1 + own / (c['process_cpu_s'] - own):.3f}",
                  flush=True)  # fmt: skip
    sim_hook.record_urban = real


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--time-limit", type=float, default=120.0)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        static_cost(a.repeats, Path(d))
        paired(a.pairs, a.time_limit, Path(d))


if __name__ == "__main__":
    main()
