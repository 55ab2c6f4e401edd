"""What the verification sweeps tell: their outcome against how far the tested candidate was
from the true source, their duration and their path.

    python benchmarks/search_verifications.py [--trials 80] [--seed 100] [--jobs 2]
        [--strategy surge-cast] [--wind estimated] [--scenario open-field]

A verification sweep (``mission/strategies/common.py``) flies crosswind a few metres upwind of
the candidate source (the most-upwind hit) and ends "verified" if it meets no plume, else
"interrupted". The table groups every sweep of every trial by the candidate's horizontal
distance from the true source (scoring only): within 3 m (a true plume end), 3-8 m (the
source is a few metres further upwind), beyond 8 m (a far-field gap or meander). It shows how
specific the sweep is, and what it costs in time and path: the path floor of a declaration.
Default seeds 100.. are the development set.
"""

from __future__ import annotations

import dev_set
import numpy as np

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from mission.evaluate import run_batch

CLASSES = ((0.0, 3.0, "<= 3 m (plume end)"), (3.0, 8.0, "3-8 m (short)"), (8.0, np.inf, "> 8 m (far field)"))


def main() -> None:
    ap = dev_set.parser(__doc__, trials=80)
    ap.add_argument("--strategy", default="surge-cast")
    ap.add_argument("--wind", default="estimated")
    ap.add_argument("--scenario", default="open-field")
    args = ap.parse_args()
    res = run_batch(args.scenario, args.strategy, args.wind, args.trials, seed=args.seed, jobs=args.jobs,
                    label=f"{args.strategy} / {args.wind}")
    sweeps = [v for r in res for v in r.verifications if v["outcome"]]
    ok = [r for r in res if r.success]
    print(f"\n{args.scenario}, {args.strategy} / {args.wind}, seeds {args.seed}..{args.seed + args.trials - 1}: "
          f"{len(ok)}/{len(res)} successful, {len(sweeps)} finished verification sweeps")
    print(f"{'candidate from source':22s} {'sweeps':>6s} {'verified':>9s} {'per trial':>9s} "
          f"{'t verified s':>12s} {'path verified m':>15s} {'t interrupted s':>15s} {'path interrupted m':>18s}")
    for lo, hi, name in CLASSES:
        cls = [v for v in sweeps if lo <= v["candidate_error_m"] < hi]
        ver = [v for v in cls if v["outcome"] == "verified"]
        intr = [v for v in cls if v["outcome"] == "interrupted"]

        def med(vs: list[dict], key: str) -> str:
            return f"{np.median([v[key] for v in vs]):.1f}" if vs else "-"

        share = f"{100 * len(ver) / len(cls):.0f} %" if cls else "-"
        print(f"{name:22s} {len(cls):6d} {share:>9s} {len(cls) / len(res):9.2f} {med(ver, 'duration_s'):>12s} "
              f"{med(ver, 'path_m'):>15s} {med(intr, 'duration_s'):>15s} {med(intr, 'path_m'):>18s}")
    if ok:
        start = ok[0].start_distance_m
        in_sweeps = [sum(v["path_m"] for v in r.verifications if v["t_start_s"] < r.time_s) / start for r in ok]
        print(f"successful trials: path in verification sweeps {np.median(in_sweeps):.2f}x the start distance "
              f"(median; total path {np.median([r.path_ratio for r in ok]):.2f}x)")


if __name__ == "__main__":
    main()
