"""Issue 20 urban search table: strategies among buildings, the supervisor routing around them.

Cells: success (declared within the strategy's success radius, horizontally) with its 95 % Wilson
score interval, crashes (collisions with a building, or a hard touchdown), the declared error
(median over every declaration, far ones included, and over the successes), the declare ratio
(path until the declaration / start distance) and the reach ratio (path until first within 2 m
of the source / start distance), both medians over the successful trials, the median time to the
declaration, failures by cause, and the wall time per mission (in-process runner, one worker).

    python benchmarks/urban_search.py --cells zigzag:paper-s4:estimated,surge-cast:paper-s4:estimated:strong-turbulence
        [--trials 50] [--seed 1000] [--jobs 1] [--cache benchmarks/urban_search_cells.json] [--no-write]

A cell is ``strategy:scenario:wind`` or ``strategy:scenario:wind:strategy-file`` (a TOML file of
``mission/strategy_files/``, by name: ``strong-turbulence``); ``--cache`` keeps every finished
cell (a re-run of the same cell and first seed replaces it) and the table, built from all cached
cells, goes into ``benchmarks/README.md`` between ``<!-- urban_search:begin -->`` and
``<!-- urban_search:end -->`` with every command that contributed. Evaluation seeds start at
1000; seeds 100-179 are for development (tuning).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from search_goals import _f, _pct, wilson, write_table  # noqa: E402

from mission.evaluate import run_batch, summarize  # noqa: E402
from mission.runners.inprocess import TrialResult  # noqa: E402

BEGIN, END = "<!-- urban_search:begin -->", "<!-- urban_search:end -->"
STRATEGY_FILES = Path(__file__).resolve().parent.parent / "mission" / "strategy_files"


def cell(results: list[TrialResult]) -> dict:
    """The summary of one cell: :func:`mission.evaluate.summarize` plus the urban figures."""
    s = summarize(results)
    declared = [r.error_m for r in results if r.declared_ned is not None]
    s.update(crashes=sum(r.cause == "crash" for r in results),
             declared=len(declared),
             declared_error_median_m=float(np.median(declared)) if declared else math.nan,
             success_radius_m=results[0].success_radius_m)  # fmt: skip
    return s


def table(cells: list[dict]) -> str:
    """The markdown table of the cached cells."""
    srank = {s: i for i, s in enumerate(("zigzag", "surge-cast", "infotaxis", "anemotaxis"))}
    wrank = {w: i for i, w in enumerate(("estimated", "oracle", "none"))}
    cells = sorted(cells, key=lambda c: (c["scenario"], srank.get(c["strategy"], 9), wrank.get(c["wind"], 9),
                                         c.get("params", "")))
    lines = ["| scenario | strategy | wind | strategy file | seeds | trials | success % [95 % CI] (radius) | crashes "
             "| declared error median m (all / successes) | declare ratio | reach ratio (2 m) | t median s "
             "| failures | wall s / mission | run | before |",
             "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---|---|"]
    for s in cells:
        fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        lo, hi = wilson(s["successes"], s["trials"])
        lines.append(
            f"| {s['scenario']} | {s['strategy']} | {s['wind']} | {s.get('params') or '-'} | {s['seed0']}.. | "
            f"{s['trials']} | "
            f"{s['successes']} = {_pct(s['success_rate'])} [{_pct(lo)}-{_pct(hi)}] ({s['success_radius_m']:g} m) | "
            f"{s['crashes']} | {_f(s['declared_error_median_m'], 1)} / {_f(s['error_median_m'], 1)} | "
            f"{_f(s['path_ratio_median'])} | {_f(s['reach_ratio_median'])} | {_f(s['time_median_s'], 0)} | "
            f"{fails} | {_f(s['wall_s_mean'], 1)} | {s['date']} | {s.get('before') or '-'} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--cells", default="", help="comma-separated strategy:scenario:wind")
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cache", default=str(Path(__file__).with_name("urban_search_cells.json")))
    ap.add_argument("--no-write", action="store_true", help="print only, do not edit benchmarks/README.md")
    args = ap.parse_args()
    cache = Path(args.cache)
    cached: list[dict] = json.loads(cache.read_text()) if cache.exists() else []
    command = "python benchmarks/" + Path(sys.argv[0]).name + " " + " ".join(sys.argv[1:])
    for spec in filter(None, args.cells.split(",")):
        parts = spec.split(":")
        if len(parts) not in (3, 4):
            sys.exit(f"--cells {spec!r}: expected strategy:scenario:wind[:strategy-file]")
        strategy, scenario, wind = parts[:3]
        params = parts[3] if len(parts) == 4 else ""
        params_path = str(STRATEGY_FILES / f"{params}.toml") if params else None
        if params_path is not None and not Path(params_path).is_file():
            sys.exit(f"--cells {spec!r}: no strategy file {params_path}")
        t0 = time.time()
        res = run_batch(scenario, strategy, wind, args.trials, seed=args.seed, jobs=args.jobs, params_path=params_path,
                        label=f"{strategy} / {wind} / {scenario} {params}")
        s = cell(res)
        s.update(seed0=args.seed, date=time.strftime("%Y-%m-%d"), command=command, wall_s=round(time.time() - t0),
                 params=params)
        key = (strategy, scenario, wind, args.seed, params)
        old = [c for c in cached if (c["strategy"], c["scenario"], c["wind"], c["seed0"], c.get("params", "")) == key]
        if old:  # the replaced figure stays beside the new one (e.g. before the blade-element world)
            s["before"] = f"{old[0]['successes']} = {_pct(old[0]['success_rate'])} ({old[0]['date']})"
        cached = [c for c in cached if c not in old]
        cached.append(s)
        cache.write_text(json.dumps(cached, indent=1, default=str))
        print(table([s]).splitlines()[-1], flush=True)
    print(write_table(table(cached), cached, BEGIN, END, "urban_search_cells.json", args.no_write))

if __name__ == "__main__":
    main()
