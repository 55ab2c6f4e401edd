"""The results row of one mission: its configuration, outcome and figures (one Parquet row).

Columns (SI units, NED; times are simulation seconds from t = 0 on the ground):

- identity: ``key``, ``campaign``, ``grid``, ``scenario`` (as in the campaign file), ``strategy``,
  ``wind``, ``seed``, ``time_limit_s`` (NaN: the scenario's duration), ``config_hash``;
- parameters: one column ``p.<name>`` per scenario or strategy parameter of the campaign (null where
  a mission does not have it); the full configuration in ``scenario_config`` and ``strategy_config``
  (JSON: the scenario table as flown, every strategy parameter);
- outcome: ``status`` (``ok``, or ``error`` with ``error``), ``success`` (declared within 5 m of the
  true source, horizontally), ``cause`` (``""`` or a failure cause: declared-far, timeout,
  geofence, crash, takeoff), ``error_m`` (declared - true, horizontal), ``declared_n/e/d``,
  ``confidence``, ``source_n/e/d``, ``start_n/e``, ``start_distance_m``, ``time_s`` (to the
  declaration), ``path_m`` / ``reach_path_m`` and their ratios to the start distance
  ``declare_ratio`` (path to the declaration) and ``reach_ratio`` (path until first within 5 m),
  ``wind_rmse_n/e/d/h`` (the strategy's wind against the truth, m/s), ``n_detections``,
  ``n_verifications``, ``end_state``;
- cost and provenance: ``cpu_s`` (CPU seconds of the mission in its worker thread), ``wall_s``,
  ``rss_mb`` (the worker's peak resident memory), ``worker``, ``finished_at`` (UTC, ISO 8601),
  ``windseek_version``, ``code_commit``, ``schema_version``.
"""

from __future__ import annotations

import functools
import json
import math
from datetime import UTC, datetime
from typing import Any

import pyarrow as pa

from mission.campaign.task import Task

#: Version of the results layout; a results folder written with another one is refused.
SCHEMA_VERSION = 1

BASE_SCHEMA = pa.schema([
    ("key", pa.string()), ("campaign", pa.string()), ("grid", pa.int32()), ("scenario", pa.string()),
    ("strategy", pa.string()), ("wind", pa.string()), ("seed", pa.int64()), ("time_limit_s", pa.float64()),
    ("config_hash", pa.string()), ("status", pa.string()), ("error", pa.string()), ("success", pa.bool_()),
    ("cause", pa.string()), ("error_m", pa.float64()), ("declared_n", pa.float64()), ("declared_e", pa.float64()),
    ("declared_d", pa.float64()), ("confidence", pa.float64()), ("source_n", pa.float64()),
    ("source_e", pa.float64()), ("source_d", pa.float64()), ("start_n", pa.float64()), ("start_e", pa.float64()),
    ("start_distance_m", pa.float64()), ("time_s", pa.float64()), ("path_m", pa.float64()),
    ("reach_path_m", pa.float64()), ("declare_ratio", pa.float64()), ("reach_ratio", pa.float64()),
    ("wind_rmse_n", pa.float64()), ("wind_rmse_e", pa.float64()), ("wind_rmse_d", pa.float64()),
    ("wind_rmse_h", pa.float64()), ("n_detections", pa.int64()), ("n_verifications", pa.int64()),
    ("end_state", pa.string()), ("cpu_s", pa.float64()), ("wall_s", pa.float64()), ("rss_mb", pa.float64()),
    ("worker", pa.string()), ("finished_at", pa.string()), ("windseek_version", pa.string()),
    ("code_commit", pa.string()), ("schema_version", pa.int32()), ("scenario_config", pa.string()),
    ("strategy_config", pa.string()),
])  # fmt: skip
PARAM_PREFIX = "p."
NAN = math.nan


def _identity(task: Task) -> dict[str, Any]:
    row: dict[str, Any] = {
        "key": task.key, "campaign": task.campaign, "grid": task.grid, "scenario": task.scenario,
        "strategy": task.strategy, "wind": task.wind, "seed": task.seed,
        "time_limit_s": NAN if task.time_limit_s is None else float(task.time_limit_s),
        "config_hash": task.config_hash, "scenario_config": json.dumps(task.scenario_table, sort_keys=True),
    }  # fmt: skip
    for name, value in task.params.items():
        row[PARAM_PREFIX + name] = value
    return row


@functools.cache
def windseek_version() -> str:
    """The installed windseek's version ("unknown" if it is not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("windseek")
    except PackageNotFoundError:
        return "unknown"


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def ok_row(task: Task, result: Any, source_ned: Any, start_ned: Any, strategy_config: dict[str, Any],
           cost: dict[str, Any]) -> dict[str, Any]:
    """The row of a flown mission (``result``: a :class:`~mission.runners.inprocess.TrialResult`)."""
    dec = result.declared_ned if result.declared_ned is not None else [NAN, NAN, NAN]
    rmse = [float(v) for v in result.wind_rmse_ned]
    row = _identity(task)
    row.update({
        "status": "ok", "error": "", "success": bool(result.success), "cause": result.cause,
        "error_m": float(result.error_m), "declared_n": float(dec[0]), "declared_e": float(dec[1]),
        "declared_d": float(dec[2]), "confidence": float(result.confidence), "source_n": float(source_ned[0]),
        "source_e": float(source_ned[1]), "source_d": float(source_ned[2]), "start_n": float(start_ned[0]),
        "start_e": float(start_ned[1]), "start_distance_m": float(result.start_distance_m),
        "time_s": float(result.time_s), "path_m": float(result.path_m), "reach_path_m": float(result.reach_path_m),
        "declare_ratio": float(result.path_ratio), "reach_ratio": float(result.reach_ratio),
        "wind_rmse_n": rmse[0], "wind_rmse_e": rmse[1], "wind_rmse_d": rmse[2],
        "wind_rmse_h": math.hypot(rmse[0], rmse[1]), "n_detections": int(result.n_detections),
        "n_verifications": len(result.verifications), "end_state": result.end_state,
        "strategy_config": json.dumps(strategy_config, sort_keys=True, default=str), "finished_at": _now(),
        "schema_version": SCHEMA_VERSION,
    })  # fmt: skip
    row.update(cost)
    return row


def error_row(task: Task, message: str, cost: dict[str, Any] | None = None) -> dict[str, Any]:
    """The row of a mission that failed to run (an exception, twice, or a worker lost too often)."""
    row = _identity(task)
    row.update({"status": "error", "error": message[:2000], "success": False, "cause": "error",
                "strategy_config": json.dumps(task.strategy_table, sort_keys=True), "finished_at": _now(),
                "schema_version": SCHEMA_VERSION})  # fmt: skip
    row.update(cost or {})
    return row


def to_table(rows: list[dict[str, Any]]) -> pa.Table:
    """Rows -> an Arrow table: the base columns typed by :data:`BASE_SCHEMA`, ``p.*`` columns inferred
    (numbers as float64, so a parameter swept as 2 and 2.5 has one type in every file)."""
    cols: dict[str, pa.Array] = {}
    for f in BASE_SCHEMA:
        cols[f.name] = pa.array([r.get(f.name) for r in rows], type=f.type)
    pnames = sorted({k for r in rows for k in r if k.startswith(PARAM_PREFIX)})
    for name in pnames:
        vals = [r.get(name) for r in rows]
        numeric = all(v is None or (isinstance(v, int | float) and not isinstance(v, bool)) for v in vals)
        if numeric:
            cols[name] = pa.array([None if v is None else float(v) for v in vals], type=pa.float64())
        elif all(v is None or isinstance(v, str) for v in vals):
            cols[name] = pa.array(vals, type=pa.string())
        else:  # booleans, vectors: kept as their JSON text
            cols[name] = pa.array([None if v is None else json.dumps(v) for v in vals], type=pa.string())
    return pa.table(cols)
