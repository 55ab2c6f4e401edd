"""Declaration strictness vs path: surge-cast with one verified end (the default) or two.

    python benchmarks/search_tradeoff.py [--trials 40] [--seed 100] [--jobs 2] [--winds estimated,oracle]
        [--scenarios open-field,open-field-high]

The issue-6 path goal (median path <= 2x the start distance) and its success goal pull apart:
every verified end costs a crosswind sweep upwind of the candidate and a cast back to
re-acquire the plume. This prints, per scenario (default: moderate and high turbulence) and
wind mode, success rate and median path / start distance of surge-cast with its defaults
(``confirmations = 1``) and with two verified ends (``confirmations = 2``). Default seeds
100.. are the development set.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import dev_set

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from mission.evaluate import run_batch, summarize

VARIANTS = {
    "defaults (confirmations 1)": "",
    "confirmations 2": "[strategy.surge-cast]\nconfirmations = 2\n",
}


def main() -> None:
    ap = dev_set.parser(__doc__, trials=40)
    ap.add_argument("--winds", default="estimated,oracle")
    ap.add_argument("--scenarios", default="open-field,open-field-high")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in args.scenarios.split(","):
            for name, toml in VARIANTS.items():
                path = None
                if toml:
                    path = str(Path(tmp) / "params.toml")
                    Path(path).write_text(toml)
                for wind in args.winds.split(","):
                    res = run_batch(scenario, "surge-cast", wind, args.trials, seed=args.seed, jobs=args.jobs,
                                    params_path=path, label=f"{scenario} / {name} / {wind}")
                    rows.append((scenario, name, wind, summarize(res)))
    print(f"\nsurge-cast, seeds {args.seed}..{args.seed + args.trials - 1}")
    print(f"{'scenario':16s} {'variant':28s} {'wind':9s} {'success':>8s} {'path/start':>10s} "
          f"{'t median':>9s}  failures")
    for scenario, name, wind, s in rows:
        fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        print(f"{scenario:16s} {name:28s} {wind:9s} {100 * s['success_rate']:7.1f}% {s['path_ratio_median']:10.2f} "
              f"{s['time_median_s']:8.0f}s  {fails}")


if __name__ == "__main__":
    main()
