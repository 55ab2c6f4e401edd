"""One mission of a campaign: its configuration and its stable key.

Kept free of simulator imports: a Dask worker unpickles tasks before anything else, and the
compiled-kernel cache must be configured before a kernel module is imported (``toolchain.numba_cache``).

The key names what the campaign asked for: the scenario as written in the campaign file, the
scenario parameters, the strategy and its knobs (and base strategy file), the wind source, the
seed, the time limit and the geofence. The same campaign file gives the same keys on every run,
so a re-run skips what is finished. The resolved configuration (the scenario table after the
parameters were set, every strategy parameter) is hashed separately (``config_hash``): if a
built-in scenario or a default changes between runs, the finished rows keep the configuration
they were flown with, and the re-run says so.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

#: Bumped when the meaning of a key changes (then no old result is taken for a new mission).
KEY_VERSION = 1


@dataclass
class Task:
    """One mission (picklable; SI units; scenario and strategy tables as TOML would give them).

    scenario: as written in the campaign file (a built-in name or an absolute .toml path).
    scenario_table: the scenario's TOML table with the parameters set (validated by the scenario parser).
    params: the swept and fixed parameters of this mission, ``{"wind_speed_m_s": 5, "surge-cast.lost_s": 2}``.
    strategy_table: the ``[strategy]`` table (base strategy file + knobs) for ``params_from_table``.
    """

    key: str
    campaign: str
    grid: int
    scenario: str
    scenario_table: dict[str, Any]
    strategy: str
    strategy_table: dict[str, Any]
    wind: str
    seed: int
    time_limit_s: float | None
    geofence_m: float
    params: dict[str, Any]
    config_hash: str


def canonical(obj: Any) -> str:
    """Sorted-key compact JSON (the hash input): equal configurations give equal text."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def task_key(scenario: str, scenario_params: dict[str, Any], strategy: str, strategy_params: dict[str, Any],
             strategy_file: str | None, wind: str, seed: int, time_limit_s: float | None, geofence_m: float) -> str:
    """The stable key of a mission (20 hex digits of SHA-256 over its canonical description)."""
    desc = {
        "v": KEY_VERSION, "scenario": scenario, "scenario_params": scenario_params, "strategy": strategy,
        "strategy_params": strategy_params, "strategy_file": strategy_file, "wind": wind, "seed": int(seed),
        "time_limit_s": time_limit_s, "geofence_m": geofence_m,
    }  # fmt: skip
    return hashlib.sha256(canonical(desc).encode()).hexdigest()[:20]


def config_hash(scenario_table: dict[str, Any], strategy_params: dict[str, Any]) -> str:
    """Hash of the resolved configuration a mission flies (scenario table + every strategy parameter)."""
    return hashlib.sha256(canonical([scenario_table, strategy_params]).encode()).hexdigest()[:16]
