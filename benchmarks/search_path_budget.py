"""Where the search path goes: finding the source vs deciding it is there.

    python benchmarks/search_path_budget.py [--trials 40] [--seed 100] [--jobs 2]
        [--strategies surge-cast,zigzag] [--winds estimated,oracle] [--scenario open-field]

For each strategy and wind mode, over the successful trials: the median path / start distance
to the declaration (the issue-6 figure, goal <= 2x) and the median path / start distance flown
until the vehicle first came within the success radius (5 m) of the source. The difference of
the two medians ("deciding") is roughly what the declaration costs (verification sweeps,
re-acquisitions at the source). Default seeds 100.. are the
development set; the true source position is used for scoring only.
"""

from __future__ import annotations

import dev_set

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from mission.evaluate import run_batch, summarize


def main() -> None:
    ap = dev_set.parser(__doc__, trials=40)
    ap.add_argument("--strategies", default="surge-cast,zigzag")
    ap.add_argument("--winds", default="estimated,oracle")
    ap.add_argument("--scenario", default="open-field")
    args = ap.parse_args()
    rows = []
    for strat in args.strategies.split(","):
        for wind in args.winds.split(","):
            res = run_batch(args.scenario, strat, wind, args.trials, seed=args.seed, jobs=args.jobs,
                            label=f"{strat} / {wind}")
            rows.append(summarize(res))
    print(f"\n{args.scenario}, seeds {args.seed}..{args.seed + args.trials - 1} (medians over successful trials)")
    print(f"{'strategy':11s} {'wind':9s} {'success':>8s} {'path/start':>10s} {'to reach 5 m':>12s} {'deciding':>9s}")
    for s in rows:
        total, reach = s["path_ratio_median"], s["reach_ratio_median"]
        print(f"{s['strategy']:11s} {s['wind']:9s} {100 * s['success_rate']:7.1f}% {total:10.2f} {reach:12.2f} "
              f"{total - reach:9.2f}")


if __name__ == "__main__":
    main()
