"""Campaign plots (PNG, matplotlib without a display): look rather than read.

- ``sweep-<param>.png``, one per swept parameter (or the scenario, when no parameter is swept):
  success rate with its 95 % Wilson interval (left) and the median declare ratio (solid) and reach
  ratio (dashed) of the successful missions (right) against the parameter, one line per strategy
  and wind source; every other parameter is pooled (the title says which).
- ``declared-map.png``: where the missions declared the source, relative to the true source, in
  the start -> source frame (x: metres past the source along the line from the start, y: metres to
  the right of it), one panel per strategy and wind source, with the 5 m success circle; a
  success is a dot, a miss a cross.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from mission.campaign.report import summarize_groups, swept_params
from mission.campaign.rows import PARAM_PREFIX

SUCCESS_RADIUS_M = 5.0


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_plots(table: pa.Table, folder: Path, x: str | None = None) -> list[Path]:
    """Write the sweep plots and the declared-position map into ``folder``; returns the files."""
    ok = table.filter(pc.equal(table.column("status"), "ok"))
    if ok.num_rows == 0:
        return []
    folder.mkdir(parents=True, exist_ok=True)
    if x is not None:
        xs = [x if x in ok.column_names else PARAM_PREFIX + x]
        if xs[0] not in ok.column_names:
            raise ValueError(f"--x {x}: no such column or parameter")
    else:
        xs = swept_params(ok) or ["scenario"]
    out = [_sweep(ok, col, folder) for col in xs]
    out.append(_declared_map(ok, folder))
    return out


def _label(col: str) -> str:
    return col[len(PARAM_PREFIX):] if col.startswith(PARAM_PREFIX) else col


def _sweep(table: pa.Table, col: str, folder: Path) -> Path:
    plt = _plt()
    groups = summarize_groups(table, ["strategy", "wind", col])
    lines: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for g in groups:
        if g[col] is not None:
            lines.setdefault((g["strategy"], g["wind"]), []).append(g)
    values = sorted({g[col] for g in groups if g[col] is not None}, key=lambda v: (isinstance(v, str), v))
    numeric = all(isinstance(v, int | float) for v in values)
    pos = {v: (float(v) if numeric else i) for i, v in enumerate(values)}
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.8))
    n_lines = max(1, len(lines))
    for i, ((strategy, wind), gs) in enumerate(sorted(lines.items())):
        # categorical x: a small offset per line so the error bars do not hide each other
        off = 0.0 if numeric else (i - (n_lines - 1) / 2) * 0.08
        xv = np.array([pos[g[col]] + off for g in gs])
        rate = np.array([100 * g["success_rate"] for g in gs])
        err = np.maximum(0.0, np.array([[100 * (g["success_rate"] - g["success_lo"]) for g in gs],
                                        [100 * (g["success_hi"] - g["success_rate"]) for g in gs]]))  # fmt: skip
        (ln,) = ax1.plot(xv, rate, marker="o", label=f"{strategy} / {wind}")
        ax1.errorbar(xv, rate, yerr=err, fmt="none", ecolor=ln.get_color(), alpha=0.5, capsize=3)
        ax2.plot(xv, [g["declare_median"] for g in gs], marker="o", color=ln.get_color(), label=f"{strategy} / {wind}")
        ax2.plot(xv, [g["reach_median"] for g in gs], marker=".", ls="--", color=ln.get_color(), alpha=0.7)
    for ax in (ax1, ax2):
        ax.set_xlabel(_label(col))
        ax.grid(alpha=0.3)
        if not numeric:
            ax.set_xticks(range(len(values)), [str(v) for v in values], rotation=20, ha="right")
    ax1.set_ylabel("success % (95 % Wilson interval)")
    ax1.set_ylim(-2, 102)
    ax2.set_ylabel("path / start distance (median, successful)")
    ax2.plot([], [], ls="--", color="grey", label="reach ratio (dashed)")
    ax1.legend(fontsize=8, loc="best")
    ax2.legend(fontsize=8, loc="best")
    pooled = [_label(c) for c in swept_params(table) if c != col]
    n = sum(g["missions"] for g in groups)
    fig.suptitle(f"{table.column('campaign')[0].as_py()}: success and path against {_label(col)} ({n} missions"
                 + (f"; pooled over {', '.join(pooled)}" if pooled else "") + ")", fontsize=10)  # fmt: skip
    fig.tight_layout()
    path = folder / f"sweep-{_label(col).replace('/', '_')}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _frame(rows: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Declared positions in the start -> source frame (x along, y to the right; source at 0), success flags."""
    xs, ys, won = [], [], []
    for r in rows:
        if r["declared_n"] is None or not math.isfinite(r["declared_n"]):
            continue
        u = np.array([r["source_n"] - r["start_n"], r["source_e"] - r["start_e"]])
        norm = float(np.hypot(*u))
        u = u / norm if norm > 0 else np.array([1.0, 0.0])
        d = np.array([r["declared_n"] - r["source_n"], r["declared_e"] - r["source_e"]])
        xs.append(float(d @ u))
        ys.append(float(d @ np.array([-u[1], u[0]])))
        won.append(bool(r["success"]))
    return np.array(xs), np.array(ys), np.array(won, dtype=bool)


def _declared_map(table: pa.Table, folder: Path) -> Path:
    plt = _plt()
    rows = table.to_pylist()
    panels: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        panels.setdefault((r["strategy"], r["wind"]), []).append(r)
    keys = sorted(panels)
    ncol = min(3, len(keys))
    nrow = math.ceil(len(keys) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 4.4 * nrow), squeeze=False)
    start = float(np.median([r["start_distance_m"] for r in rows if r["start_distance_m"] is not None]))
    for ax, key in zip(axes.flat, keys, strict=False):
        x, y, won = _frame(panels[key])
        n = len(panels[key])
        ax.add_patch(plt.Circle((0, 0), SUCCESS_RADIUS_M, fill=False, color="green", ls="--", lw=1))
        ax.scatter(x[won], y[won], s=10, c="tab:blue", alpha=0.6, label=f"success ({int(won.sum())})")
        ax.scatter(x[~won], y[~won], s=22, c="tab:red", marker="x", label=f"declared, missed ({int((~won).sum())})")
        ax.plot([0], [0], marker="*", ms=14, color="black", ls="none", label="true source")
        ax.plot([-start], [0], marker="^", ms=9, color="grey", ls="none", label=f"start (median {start:.0f} m)")
        ax.set_title(f"{key[0]} / {key[1]}: {n} missions, {len(x)} declared", fontsize=9)
        span = max(15.0, min(start * 1.15, float(np.nanmax(np.abs(np.r_[x, y, 0.0]))) * 1.1))
        ax.set_xlim(-max(span, start * 1.1), span)
        ax.set_ylim(-span, span)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("m past the source, along start -> source")
        ax.set_ylabel("m to the right")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    for ax in list(axes.flat)[len(keys):]:
        ax.axis("off")
    fig.suptitle(f"{rows[0]['campaign']}: declared source positions relative to the true source", fontsize=10)
    fig.tight_layout()
    path = folder / "declared-map.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
