"""Declaration strictness vs path: surge-cast with two verified ends (the default) or one.

    python benchmarks/search_tradeoff.py [--trials 40] [--seed 100] [--jobs 2] [--winds estimated,oracle]

The issue-6 path goal (median path <= 2x the start distance) and its success goal pull apart:
every verified end costs a crosswind sweep and a cast back. This prints, for open-field
(moderate turbulence), success rate and median path / start distance of surge-cast with its
defaults (``confirmations = 2``) and with one verified end of four legs
(``confirmations = 1``, ``verify_legs = 4``). Default seeds 100.. are the development set.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from mission.evaluate import run_batch, summarize

VARIANTS = {
    "defaults (confirmations 2)": "",
    "confirmations 1, verify_legs 4": "[strategy]\nconfirmations = 1\n[strategy.surge-cast]\nverify_legs = 4\n",
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--winds", default="estimated,oracle")
    ap.add_argument("--scenario", default="open-field")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, toml in VARIANTS.items():
            path = None
            if toml:
                path = str(Path(tmp) / "params.toml")
                Path(path).write_text(toml)
            for wind in args.winds.split(","):
                res = run_batch(args.scenario, "surge-cast", wind, args.trials, seed=args.seed, jobs=args.jobs,
                                params_path=path, label=f"{name} / {wind}")
                s = summarize(res)
                rows.append((name, wind, s))
    print(f"\nsurge-cast, {args.scenario}, seeds {args.seed}..{args.seed + args.trials - 1}")
    print(f"{'variant':32s} {'wind':9s} {'success':>8s} {'path/start':>10s} {'t median':>9s}  failures")
    for name, wind, s in rows:
        fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        print(f"{name:32s} {wind:9s} {100 * s['success_rate']:7.1f}% {s['path_ratio_median']:10.2f} "
              f"{s['time_median_s']:8.0f}s  {fails}")


if __name__ == "__main__":
    main()
