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
        "processes and print the success rate (declared within 5 m of the true source, horizontally; 3 m "
        "for infotaxis), median and 90th-percentile time to declaration, the median path flown until the "
        "declaration and until first within 2 m of the source over the start distance, failures by cause, "
        "and for infotaxis how often its 90 % credible region held the source.",
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
    p.add_argument("--vehicle", default=None, help="vehicle file (name or path) of the estimator's force model, e.g. "
                   "one written by `windseek identify` (default: the scenario vehicle's own model)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout (summary + trials; it says "
                   "which truth the world flew and which model the estimator used)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _fmt(v: float, unit: str = "", nd: int = 1) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{nd}f}{unit}"



def run(args: argparse.Namespace) -> int:
    from mission.evaluate import run_batch, summarize

    results = run_batch(
        args.scenario, args.strategy, args.wind, args.trials, seed=args.seed, jobs=args.jobs,
        params_path=args.params, time_limit_s=args.time_limit, progress=not (args.json or args.no_progress),
        model=args.vehicle,
    )
    s = summarize(results)
    if args.json:
        out = dict(s)
        out["results"] = [r.to_dict() for r in results]
        print(json.dumps(json_safe(out), allow_nan=False))
        return 0
    print(f"{s['strategy']} with {s['wind']} wind on {s['scenario']}: {s['trials']} trials")
    if s["estimator_model"]:
        print(f"  world: {s['world_truth']}; estimator model: {s['estimator_model']}")
    radius = results[0].success_radius_m
    print(f"  success rate: {100 * s['success_rate']:.0f} % ({s['successes']}/{s['trials']} declared within "
          f"{radius:g} m; within 3 m {100 * s['within_3m_rate']:.0f} %, within 5 m {100 * s['within_5m_rate']:.0f} %)")
    print(f"  time to declaration: median {_fmt(s['time_median_s'], ' s')}, 90th percentile "
          f"{_fmt(s['time_p90_s'], ' s')} (successful trials)")
    print(f"  path / start distance (successful trials): median {_fmt(s['path_ratio_median'], '', 2)} to the "
          f"declaration, {_fmt(s['reach_ratio_median'], '', 2)} until first within 2 m of the source "
          f"({s['never_reached']} never within 2 m); declaration error: median {_fmt(s['error_median_m'], ' m')}")
    if not math.isnan(s["credible_coverage"]):
        print(f"  credible region (90 %): held the source in {100 * s['credible_coverage']:.0f} % of declarations, "
              f"median radius {_fmt(s['credible_radius_median_m'], ' m')}, mean confidence "
              f"{_fmt(s['confidence_mean'], '', 2)}")
    fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "none"
    print(f"  failures by cause: {fails}")
    return 0
