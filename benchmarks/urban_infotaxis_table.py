"""Issue 32 table: the urban-aware infotaxis in the city, from ``windseek search --json`` outputs.

The evaluation runs in chunks of 10 seeds per cell (a chunk that finished is kept whatever happens
to the next; the machine is shared)::

    windseek search paper-s4 --strategy infotaxis --params mission/strategy_files/urban.toml \\
        --trials 10 --seed 1000 --jobs 1 --json > paper-s4_1000.json      # 1010, 1020, ...

and this script merges the chunks of each cell: success (declared within 3 m) with its 95 % Wilson
interval, within 5 m, how often the 90 % credible region held the source among the declarations
(the calibration goal: 85-95 %), the mean stated confidence, failures by cause, the median time to
a successful declaration and the wall time per mission.

    python benchmarks/urban_infotaxis_table.py paper-s4_*.json paper-s4-wind90_*.json ...
"""

from __future__ import annotations

import json
import math
import sys
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from search_goals import wilson  # noqa: E402


def _row(scenario: str, results: list[dict], seeds: list[int]) -> str:
    """One markdown row of a cell's merged results."""
    n = len(results)
    ok = sum(bool(r["success"]) for r in results)
    lo, hi = wilson(ok, n)
    declared = [r for r in results if r.get("declared_ned") is not None]
    held = sum(bool(r.get("credible_contains")) for r in declared)
    within5 = sum(1 for r in declared if r["error_m"] <= 5.0)
    conf = f"{sum(float(r['confidence']) for r in declared) / len(declared):.2f}" if declared else "-"
    cov = f"{held} / {len(declared)} = {100 * held / len(declared):.0f} %" if declared else "-"
    fails = Counter(r["cause"] for r in results if not r["success"])
    times = sorted(float(r["time_s"]) for r in results if r["success"])
    t_med = f"{times[len(times) // 2]:.0f}" if times else "-"
    wall = sum(float(r.get("wall_s", math.nan)) for r in results) / max(n, 1)
    fail = ", ".join(f"{k} {v}" for k, v in sorted(fails.items())) or "-"
    return (f"| {scenario} | {min(seeds)}-{max(seeds)} | {n} | {ok} = {100 * ok / n:.0f} % [{100 * lo:.0f}-"
            f"{100 * hi:.0f}] | {100 * within5 / n:.0f} % | {cov} | {conf} | {fail} | {t_med} | {wall:.1f} |")


def main() -> None:
    cells: dict[str, list[dict]] = defaultdict(list)
    for f in sys.argv[1:]:
        d = json.loads(Path(f).read_text())
        cells[d["scenario"]] += d["results"]
    print("| scenario | seeds | trials | within 3 m [95 % CI] | within 5 m | 90 % region held / declared | mean "
          "confidence | failures | t median s (successes) | wall s / mission |")
    print("|---|---|---:|---:|---:|---:|---:|---|---:|---:|")
    for scenario, results in sorted(cells.items()):
        print(_row(scenario, results, [int(r["seed"]) for r in results]))


if __name__ == "__main__":
    main()
