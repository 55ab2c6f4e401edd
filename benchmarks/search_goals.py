"""Issue 19 search table: every strategy with both path measures, per scenario and wind mode.

Cells: success (declared within the strategy's success radius: 3 m for infotaxis, 5 m for the
bio-inspired strategies; with its 95 % Wilson score interval) and the shares declared within 3 m
and within 5 m; the declare ratio (path until the declaration / start distance) and the reach
ratio (path until the vehicle first came within 2 m of the source / start distance; infinite if
it never did), both medians over the successful trials; the median time to declaration
(successful trials); for infotaxis the share of declarations whose 90 % credible region held
the source and the mean stated confidence; failures by cause.

    python benchmarks/search_goals.py --cells infotaxis:open-field:estimated,surge-cast:open-field:oracle,...
        [--trials 50] [--seed 1000] [--jobs 1] [--cache benchmarks/search_goals_cells.json] [--no-write]

A cell is ``strategy:scenario:wind``. ``--cache`` keeps every finished cell (JSON) and the table
is built from all cached cells, so a long table runs in pieces; a cell is keyed by strategy,
scenario, wind and first seed (a re-run replaces it). The table goes into ``benchmarks/README.md``
between ``<!-- search_goals:begin -->`` and ``<!-- search_goals:end -->`` with the command line
of every run that contributed. Evaluation seeds start at 1000; seeds 100-179 and 200-299 are for development.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from mission.evaluate import run_batch, summarize

BEGIN, END = "<!-- search_goals:begin -->", "<!-- search_goals:end -->"
ORDER = ("open-field", "open-field-high", "open-field-far", "open-field-shift", "paper-anemotaxis",
         "open-field-low", "open-field-stable", "open-field-unstable")


def _f(v: float | None, nd: int = 2) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return "inf" if v == math.inf else f"{v:.{nd}f}"


def _pct(v: float) -> str:
    return "-" if v != v else f"{100 * v:.0f}"


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval (95 % for z = 1.96) of a success share k / n."""
    if n == 0:
        return math.nan, math.nan
    p, z2 = k / n, z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def table(cells: list[dict]) -> str:
    """The markdown table of the cached cells."""
    srank = {s: i for i, s in enumerate(("infotaxis", "surge-cast", "zigzag", "anemotaxis"))}
    wrank = {w: i for i, w in enumerate(("estimated", "oracle", "none"))}
    cells = sorted(cells, key=lambda c: (ORDER.index(c["scenario"]) if c["scenario"] in ORDER else 99,
                                         c["scenario"], srank.get(c["strategy"], 9), wrank.get(c["wind"], 9)))
    lines = ["| scenario | strategy | wind | seeds | trials | success % [95 % CI] (radius) | within 3 m % "
             "| within 5 m % | declare ratio | reach ratio (2 m) | never within 2 m | 90 % region held % | confidence "
             "| t median s | failures |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for s in cells:
        fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        lo, hi = wilson(s["successes"], s["trials"])
        lines.append(
            f"| {s['scenario']} | {s['strategy']} | {s['wind']} | {s['seed0']}.. | {s['trials']} | "
            f"{_pct(s['success_rate'])} [{_pct(lo)}-{_pct(hi)}] ({s['success_radius_m']:g} m) | "
            f"{_pct(s['within_3m_rate'])} | "
            f"{_pct(s['within_5m_rate'])} | {_f(s['path_ratio_median'])} | {_f(s['reach_ratio_median'])} | "
            f"{s['never_reached']} | {_pct(s['credible_coverage'])} | {_f(s['confidence_mean'])} | "
            f"{_f(s['time_median_s'], 0)} | {fails} |")
    return "\n".join(lines)


def write_table(text: str, cached: list[dict], begin: str, end: str, cache_name: str, no_write: bool) -> str:
    """The table block (the table and the command line of every cached cell) written into
    benchmarks/README.md between ``begin`` and ``end`` (appended without them) unless ``no_write``;
    returns the table."""
    commands = sorted({c["command"] for c in cached})
    note = f"Produced by (every cell is kept in `benchmarks/{cache_name}`):"
    block = "\n".join([begin, "", text, "", note, "", *[f"    {c}" for c in commands], "", end])
    if not no_write:
        readme = Path(__file__).with_name("README.md")
        body = readme.read_text()
        if begin in body and end in body:
            body = body[:body.index(begin)] + block + body[body.index(end) + len(end):]
        else:
            body = body.rstrip("\n") + "\n\n" + block + "\n"
        readme.write_text(body)
    return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", default="", help="comma-separated strategy:scenario:wind")
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cache", default=str(Path(__file__).with_name("search_goals_cells.json")))
    ap.add_argument("--no-write", action="store_true", help="print only, do not edit benchmarks/README.md")
    args = ap.parse_args()
    cache = Path(args.cache)
    cached: list[dict] = json.loads(cache.read_text()) if cache.exists() else []
    command = "python benchmarks/" + Path(sys.argv[0]).name + " " + " ".join(sys.argv[1:])
    for spec in filter(None, args.cells.split(",")):
        strategy, scenario, wind = spec.split(":")
        t0 = time.time()
        res = run_batch(scenario, strategy, wind, args.trials, seed=args.seed, jobs=args.jobs,
                        label=f"{strategy} / {wind} / {scenario}")
        s = summarize(res)
        s.update(seed0=args.seed, date=time.strftime("%Y-%m-%d"), command=command,
                 success_radius_m=res[0].success_radius_m, wall_s=round(time.time() - t0))
        key = (strategy, scenario, wind, args.seed)
        cached = [c for c in cached if (c["strategy"], c["scenario"], c["wind"], c["seed0"]) != key]
        cached.append(s)
        cache.write_text(json.dumps(cached, indent=1, default=str))
        print(table([s]).splitlines()[-1], flush=True)
    print(write_table(table(cached), cached, BEGIN, END, "search_goals_cells.json", args.no_write))

if __name__ == "__main__":
    main()
