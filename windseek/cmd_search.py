"""``windseek search SCENARIO --strategy NAME``: seeded source-search trials in lockstep."""

from __future__ import annotations

import argparse
import json
import math

from mission.strategies import STRATEGIES
from mission.wind_modes import INPROCESS_WIND_MODES
from wire.jsonsafe import json_safe


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "search",
        help="run seeded source-search trials (simulator + estimator + strategy in lockstep)",
        description="Run N seeded trials of a source-seeking strategy on a plume scenario in parallel "
        "processes and print the success rate (declared within 5 m of the true source, horizontally), "
        "median and 90th-percentile time to declaration, median path length over the start distance, "
        "and failures by cause.",
    )
    p.add_argument("scenario", help="built-in scenario name (e.g. open-field) or path to a scenario .toml")
    p.add_argument("--strategy", required=True, choices=sorted(STRATEGIES), help="search strategy")
    p.add_argument("--wind", default="estimated", choices=INPROCESS_WIND_MODES,
                   help="wind information: the estimator's (default), the simulator's true mean (oracle, "
                   "comparison only) or none (pure chemotaxis)")
    p.add_argument("--trials", type=int, default=10, help="number of trials (default 10)")
    p.add_argument("--seed", type=int, default=None, help="seed of the first trial (default: the scenario's); "
                   "trial i uses seed + i")
    p.add_argument("--jobs", type=int, default=1, help="parallel processes (default 1)")
    p.add_argument("--params", default=None, help="strategy file (TOML with a [strategy] table)")
    p.add_argument("--time-limit", type=float, default=None, help="simulated seconds per trial "
                   "(default: the scenario's duration)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout (summary + trials)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _fmt(v: float, unit: str = "", nd: int = 1) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{nd}f}{unit}"



def run(args: argparse.Namespace) -> int:
    from mission.evaluate import run_batch, summarize

    results = run_batch(
        args.scenario, args.strategy, args.wind, args.trials, seed=args.seed, jobs=args.jobs,
        params_path=args.params, time_limit_s=args.time_limit, progress=not (args.json or args.no_progress),
    )
    s = summarize(results)
    if args.json:
        out = dict(s)
        out["results"] = [r.to_dict() for r in results]
        print(json.dumps(json_safe(out), allow_nan=False))
        return 0
    print(f"{s['strategy']} with {s['wind']} wind on {s['scenario']}: {s['trials']} trials")
    print(f"  success rate: {100 * s['success_rate']:.0f} % ({s['successes']}/{s['trials']} declared within 5 m)")
    print(f"  time to declaration: median {_fmt(s['time_median_s'], ' s')}, 90th percentile "
          f"{_fmt(s['time_p90_s'], ' s')} (successful trials)")
    print(f"  path / start distance: median {_fmt(s['path_ratio_median'], '', 2)} "
          f"({_fmt(s['reach_ratio_median'], '', 2)} until first within 5 m of the source); "
          f"declaration error: median {_fmt(s['error_median_m'], ' m')}")
    fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "none"
    print(f"  failures by cause: {fails}")
    return 0
