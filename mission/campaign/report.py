"""Campaign tables: success with a 95 % Wilson interval, median and p90 of the path ratios, by any grouping.

Per group (rows with ``status == "ok"``; errors are counted apart): missions, successes, the success
rate and its 95 % Wilson score interval, and over the successful missions the median and 90th
percentile of the declare ratio (path to the declaration / start distance), of the reach ratio
(path until first within 5 m of the source / start distance) and of the time to the declaration
[s]; the median declared error [m] (successful missions), the median horizontal wind RMSE [m/s]
(all missions with wind information), failures by cause and the mean CPU seconds per mission.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np
import pyarrow as pa

from mission.campaign.rows import PARAM_PREFIX
from mission.campaign.spec import CampaignError

BASE_GROUPS = ("scenario", "strategy", "wind")
Z95 = 1.959963984540054


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a proportion k / n (95 % by default); (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def swept_params(table: pa.Table) -> list[str]:
    """``p.*`` columns that take more than one value among the finished missions."""
    out = []
    for name in table.column_names:
        if name.startswith(PARAM_PREFIX):
            vals = {v for v in table.column(name).to_pylist() if v is not None}
            if len(vals) > 1:
                out.append(name)
    return out


def group_columns(table: pa.Table, names: list[str] | None) -> list[str]:
    """The grouping columns: as named (a parameter by its name, without ``p.``), or by default
    scenario, strategy, wind and every swept parameter."""
    if names is None:
        return [*BASE_GROUPS, *swept_params(table)]
    cols = []
    for n in (s.strip() for s in names if s.strip()):
        if n in table.column_names:
            cols.append(n)
        elif PARAM_PREFIX + n in table.column_names:
            cols.append(PARAM_PREFIX + n)
        else:
            params = [c[len(PARAM_PREFIX):] for c in table.column_names if c.startswith(PARAM_PREFIX)]
            raise CampaignError(f"--by {n}: no such column; columns: {', '.join([*BASE_GROUPS, 'seed', *params])}")
    return cols


def _order(v: Any) -> tuple[int, Any]:
    if v is None:
        return (2, "")
    if isinstance(v, int | float) and not isinstance(v, bool):
        return (0, float(v))
    return (1, str(v))


def _stat(values: list[float], q: float) -> float:
    arr = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    return float(np.percentile(arr, q)) if arr.size else math.nan


def summarize_groups(table: pa.Table, by: list[str]) -> list[dict[str, Any]]:
    """One summary dict per group (keys: the group columns, then the figures of the module docstring)."""
    rows = table.to_pylist()
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(tuple(r.get(c) for c in by), []).append(r)
    out = []
    for key in sorted(groups, key=lambda k: tuple(_order(v) for v in k)):
        rs = groups[key]
        ok = [r for r in rs if r["status"] == "ok"]
        won = [r for r in ok if r["success"]]
        lo, hi = wilson(len(won), len(ok))
        s: dict[str, Any] = dict(zip(by, key, strict=True))
        s.update({
            "missions": len(ok), "errors": len(rs) - len(ok), "successes": len(won),
            "success_rate": len(won) / len(ok) if ok else math.nan, "success_lo": lo, "success_hi": hi,
            "seeds": f"{min(r['seed'] for r in rs)}-{max(r['seed'] for r in rs)}",
            "failures": dict(sorted(Counter(r["cause"] for r in ok if not r["success"]).items())),
            "cpu_s_mean": float(np.mean([r["cpu_s"] for r in ok])) if ok else math.nan,
        })  # fmt: skip
        for col, label in (("declare_ratio", "declare"), ("reach_ratio", "reach"), ("time_s", "time")):
            vals = [r[col] for r in won]
            s[f"{label}_median"], s[f"{label}_p90"] = _stat(vals, 50), _stat(vals, 90)
        s["error_median_m"] = _stat([r["error_m"] for r in won], 50)
        s["wind_rmse_h_median"] = _stat([r["wind_rmse_h"] for r in ok], 50)
        out.append(s)
    return out


def _f(v: float, nd: int = 2) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return "-" if v is None else str(v)


def table_rows(groups: list[dict[str, Any]], by: list[str]) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the printed table."""
    head = [c[len(PARAM_PREFIX):] if c.startswith(PARAM_PREFIX) else c for c in by]
    head += ["n", "success % [95 % CI]", "declare ratio med / p90", "reach ratio med / p90", "t med / p90 s",
             "error med m", "wind RMSE m/s", "failures"]  # fmt: skip
    out = []
    for s in groups:
        fails = ", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "-"
        if s["errors"]:
            fails += f"; {s['errors']} errors"
        sr = "-" if s["missions"] == 0 else (f"{100 * s['success_rate']:.0f} [{100 * s['success_lo']:.0f}-"
                                             f"{100 * s['success_hi']:.0f}]")  # fmt: skip
        out.append([*(_cell(s[c]) for c in by), str(s["missions"]), sr,
                    f"{_f(s['declare_median'])} / {_f(s['declare_p90'])}", f"{_f(s['reach_median'])} / "
                    f"{_f(s['reach_p90'])}", f"{_f(s['time_median'], 0)} / {_f(s['time_p90'], 0)}",
                    _f(s["error_median_m"], 1), _f(s["wind_rmse_h_median"], 2), fails])  # fmt: skip
    return head, out


def markdown(groups: list[dict[str, Any]], by: list[str]) -> str:
    """The table as Markdown (numbers right-aligned)."""
    head, rows = table_rows(groups, by)
    align = ["---"] * len(by) + ["---:"] * (len(head) - len(by) - 1) + ["---"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def print_table(groups: list[dict[str, Any]], by: list[str], markdown_out: bool = False) -> None:
    """Print the table (rich on a terminal, plain text otherwise, or Markdown)."""
    if markdown_out:
        print(markdown(groups, by))
        return
    from rich.console import Console
    from rich.table import Table

    head, rows = table_rows(groups, by)
    t = Table(title="success: declared within 5 m of the true source; ratios and times over the successful "
              "missions; wind RMSE over all", title_justify="left")  # fmt: skip
    for i, h in enumerate(head):
        t.add_column(h, justify="left" if i < len(by) or i == len(head) - 1 else "right", no_wrap=i < len(by))
    for r in rows:
        t.add_row(*r)
    console = Console()
    (console if console.is_terminal else Console(width=220)).print(t)
