"""Search table: strategy x wind mode x turbulence level, N seeded trials per cell.

Writes a markdown table into ``benchmarks/README.md`` between the markers
``<!-- search_table:begin -->`` and ``<!-- search_table:end -->`` (appended if absent) and
prints it. Cells: success rate (declared within 5 m of the true source, horizontally),
median / 90th-percentile time to declaration (s, successful trials), median path length over
the start distance, failures by cause. Scenarios: open-field-low / open-field / open-field-high
(sigma_u 0.5 / 1.0 / 2.0 m/s; 5 m/s from the north, source 60 m upwind, stability D).

    python benchmarks/search_table.py [--trials 50] [--estimated-trials 50] [--jobs 2] [--no-write]
        [--extra open-field-shift,...] [--cache rows.json]

``--cache FILE`` keeps every finished cell in FILE (JSON) and builds the table from all the
cells there, so a long table can be run in pieces (``--levels moderate`` first, then the rest);
a cell is keyed by strategy, wind, scenario and first seed, a re-run replaces it. ``--extra``
adds rows for other scenarios (``--extra-strategies``, ``--extra-winds``, ``--extra-trials``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from mission.evaluate import run_batch, summarize

STRATEGIES = ("surge-cast", "zigzag", "anemotaxis")
WINDS = ("estimated", "oracle", "none")
LEVELS = (("low", "open-field-low"), ("moderate", "open-field"), ("high", "open-field-high"))
BEGIN, END = "<!-- search_table:begin -->", "<!-- search_table:end -->"


def _f(v: float, nd: int = 0) -> str:
    return "-" if v != v else f"{v:.{nd}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=50, help="trials per oracle/none cell")
    ap.add_argument("--estimated-trials", type=int, default=50, help="trials per estimated-wind cell")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1000, help="seed of the first trial of every cell")
    ap.add_argument("--strategies", default=",".join(STRATEGIES))
    ap.add_argument("--winds", default=",".join(WINDS))
    ap.add_argument("--levels", default=",".join(name for name, _ in LEVELS))
    ap.add_argument("--no-write", action="store_true", help="print only, do not edit benchmarks/README.md")
    ap.add_argument("--json", default=None, help="also write the summaries to this JSON file")
    ap.add_argument("--cache", default=None, help="JSON file of finished cells, read and updated (run in pieces)")
    ap.add_argument("--extra", default="", help="extra scenarios (comma-separated), e.g. open-field-shift")
    ap.add_argument("--extra-strategies", default="surge-cast")
    ap.add_argument("--extra-winds", default="estimated,oracle")
    ap.add_argument("--extra-trials", type=int, default=20)
    ap.add_argument("--title-note", default="", help="text added to the table caption")
    ap.add_argument("--notes", default=None, help="markdown file appended below the table (findings, missing cells)")
    args = ap.parse_args()
    levels = [lv for lv in LEVELS if lv[0] in args.levels.split(",")]
    cells = [(strat, wind, level, scenario, args.estimated_trials if wind == "estimated" else args.trials)
             for strat in args.strategies.split(",") if strat
             for wind in args.winds.split(",") if wind
             for level, scenario in levels]
    for scenario in filter(None, args.extra.split(",")):
        cells += [(strat, wind, "moderate" if scenario != "open-field-low" else "low", scenario, args.extra_trials)
                  for strat in args.extra_strategies.split(",") for wind in args.extra_winds.split(",")]
    cached: list[dict] = []
    if args.cache and Path(args.cache).exists():
        cached = json.loads(Path(args.cache).read_text())
    rows = []
    for strat, wind, level, scenario, n in cells:
        res = run_batch(scenario, strat, wind, n, seed=args.seed, jobs=args.jobs,
                        label=f"{strat} / {wind} / {level}")
        s = summarize(res)
        s["level"] = level
        s["seed0"] = args.seed
        s["date"] = time.strftime("%Y-%m-%d")
        rows.append(s)
        if args.cache:
            key = (s["strategy"], s["wind"], s["scenario"], s["seed0"])
            cached = [c for c in cached if (c["strategy"], c["wind"], c["scenario"], c.get("seed0")) != key]
            cached.append(s)
            Path(args.cache).write_text(json.dumps(cached, indent=1, default=str))
        fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        print(f"{strat:10s} {wind:9s} {level:8s} n={n:3d} success {100 * s['success_rate']:5.1f} % "
              f"t50 {_f(s['time_median_s'])} s t90 {_f(s['time_p90_s'])} s "
              f"path {_f(s['path_ratio_median'], 2)} fails: {fails}", flush=True)
    if args.cache:
        order = {name: i for i, name in enumerate([sc for _, sc in LEVELS])}
        srank = {name: i for i, name in enumerate(("anemotaxis", "surge-cast", "zigzag"))}
        wrank = {name: i for i, name in enumerate(WINDS)}
        rows = sorted(cached, key=lambda c: (c.get("seed0", 0), order.get(c["scenario"], 99), c["scenario"],
                                             srank.get(c["strategy"], 9), wrank.get(c["wind"], 9)))
    lines = [
        BEGIN,
        "",
        "## Source search: strategy x wind x turbulence (`benchmarks/search_table.py`)",
        "",
        "Scenarios open-field-low / open-field / open-field-high (turbulence low / moderate / high) and the "
        "extra scenarios named in the table; the first seed of each cell in the `seeds` column (trial i uses "
        f"seed + i). {args.title_note}"
        "Success: declared within 5 m of the true source (horizontal). Times (s from t = 0 on the ground) and "
        "path / start distance are medians over the successful trials.",
        "",
        "| scenario | strategy | wind | seeds | trials | success % | t median s | t p90 s | path / start | failures |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for s in rows:
        fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        lines.append(
            f"| {s['scenario']} | {s['strategy']} | {s['wind']} | {s.get('seed0', '')}.. | {s['trials']} | "
            f"{100 * s['success_rate']:.0f} | "
            f"{_f(s['time_median_s'])} | {_f(s['time_p90_s'])} | {_f(s['path_ratio_median'], 2)} | {fails} |"
        )
    if args.notes:
        lines += ["", Path(args.notes).read_text().strip()]
    lines += ["", END]
    table = "\n".join(lines)
    print(table)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    if not args.no_write:
        readme = Path(__file__).with_name("README.md")
        text = readme.read_text() if readme.exists() else "# Benchmarks\n"
        if BEGIN in text and END in text:
            a, b = text.index(BEGIN), text.index(END) + len(END)
            text = text[:a] + table + text[b:]
        else:
            text = text.rstrip("\n") + "\n\n" + table + "\n"
        readme.write_text(text)


if __name__ == "__main__":
    main()
