"""Campaign files: which missions to fly, as a grid (or a union of grids) of configurations.

A campaign file is TOML::

    [campaign]
    name = "wind-speed-sweep"          # required: names the results
    description = "..."
    scenarios = ["open-field"]         # built-in names or .toml paths (relative to this file)
    strategies = ["surge-cast", "zigzag"]
    winds = ["estimated", "oracle"]    # default ["estimated"]
    seeds = { start = 1000, count = 50 }   # or a list [1000, 1001, ...]
    time_limit_s = 300                 # optional (default: the scenario's duration)
    strategy_file = "my.toml"          # optional base strategy file ([strategy] table)

    [campaign.scenario]                # scenario parameters: a value, a list, or a range
    wind_speed_m_s = [3, 5, 8]
    turbulence_intensity = { start = 0.1, stop = 0.3, step = 0.1 }   # stop included
    "plume.sensor.detection_limit_mg_m3" = 0.05

    [campaign.strategy]                # strategy knobs: common ones, or "<strategy>.<knob>"
    altitude_m = [2.0, 3.0]
    "surge-cast.cast_half_width_m" = { start = 2, stop = 6, num = 3 }

    [[grid]]                           # optional: several grids; each inherits [campaign]'s keys
    scenarios = ["open-field-far"]
    seeds = { start = 1000, count = 20 }

Without ``[[grid]]`` the ``[campaign]`` table is the one grid. A ``[grid.scenario]`` or
``[grid.strategy]`` table adds to (and overrides names of) the campaign's. Every mistake is a
:class:`CampaignError` naming the file and the field; the values themselves are validated when the
grid is expanded (:mod:`mission.campaign.grid`), by the scenario and strategy parsers.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mission.campaign.scenario_params import check_name
from mission.strategies import STRATEGIES
from mission.wind_modes import INPROCESS_WIND_MODES
from sitl.parsing import ScenarioError

GRID_KEYS = {"scenarios", "strategies", "winds", "seeds", "time_limit_s", "strategy_file", "scenario", "strategy"}
CAMPAIGN_KEYS = GRID_KEYS | {"name", "description", "geofence_m"}
#: Most values one swept parameter may take (a typo in a range should not make a million missions).
MAX_VALUES = 10_000


class CampaignError(ValueError):
    """A campaign file, its results or its cluster is unusable; the message is one line naming the field."""


Value = float | int | str | bool | list[Any]


@dataclass(frozen=True)
class Grid:
    """One grid of a campaign: every combination of its lists is a mission."""

    index: int
    scenarios: tuple[str, ...]
    strategies: tuple[str, ...]
    winds: tuple[str, ...]
    seeds: tuple[int, ...]
    time_limit_s: float | None
    strategy_file: str | None
    scenario_params: tuple[tuple[str, tuple[Value, ...]], ...]
    strategy_params: tuple[tuple[str, tuple[Value, ...]], ...]


@dataclass(frozen=True)
class CampaignSpec:
    name: str
    description: str
    path: str
    geofence_m: float
    grids: tuple[Grid, ...]


def load_campaign(path: str | Path) -> CampaignSpec:
    """Read and check a campaign file (see the module docstring)."""
    p = Path(path)
    if not p.is_file():
        raise CampaignError(f"campaign file {p} does not exist")
    try:
        data = tomllib.loads(p.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as e:
        raise CampaignError(f"{p}: not a TOML text file (byte {e.start} is not UTF-8)") from None
    except tomllib.TOMLDecodeError as e:
        raise CampaignError(f"{p}: TOML syntax error: {e}") from None
    return parse_campaign(data, p)


def parse_campaign(data: dict[str, Any], path: Path) -> CampaignSpec:
    """A :class:`CampaignSpec` from a parsed campaign file at ``path`` (relative paths resolve from its folder)."""
    unknown = set(data) - {"campaign", "grid"}
    if unknown:
        raise CampaignError(f"{path}: unknown top-level key(s) {', '.join(sorted(unknown))}; allowed: campaign, grid")
    camp = data.get("campaign")
    if not isinstance(camp, dict):
        raise CampaignError(f"{path}: a [campaign] table is required")
    _keys(path, "campaign", camp, CAMPAIGN_KEYS)
    name = camp.get("name")
    if not isinstance(name, str) or not name.strip() or any(c in name for c in "/\\\0"):
        raise CampaignError(f"{path}: campaign.name = {name!r}: expected a non-empty name without slashes")
    geofence = camp.get("geofence_m", 250.0)
    if isinstance(geofence, bool) or not isinstance(geofence, int | float) or not 10.0 <= geofence <= 1e5:
        raise CampaignError(f"{path}: campaign.geofence_m = {geofence!r}: allowed range is [10, 100000] m")
    raw_grids = data.get("grid", [{}])
    if not isinstance(raw_grids, list) or not raw_grids:
        raise CampaignError(f"{path}: grid: expected [[grid]] tables")
    grids = []
    for i, g in enumerate(raw_grids):
        where = f"grid[{i}]" if "grid" in data else "campaign"
        if not isinstance(g, dict):
            raise CampaignError(f"{path}: {where}: expected a table")
        _keys(path, where, g, GRID_KEYS)
        grids.append(_grid(path, where, i, camp, g))
    return CampaignSpec(name.strip(), str(camp.get("description", "")), str(path), float(geofence), tuple(grids))


def _keys(path: Path, where: str, tbl: dict[str, Any], allowed: set[str]) -> None:
    unknown = set(tbl) - allowed
    if unknown:
        raise CampaignError(f"{path}: [{where}]: unknown key(s) {', '.join(sorted(unknown))}; "
                            f"allowed: {', '.join(sorted(allowed))}")  # fmt: skip


def _grid(path: Path, where: str, index: int, camp: dict[str, Any], g: dict[str, Any]) -> Grid:
    def get(key: str, default: Any = None) -> Any:
        return g.get(key, camp.get(key, default))

    def names(key: str, allowed: tuple[str, ...] | None, default: Any = None) -> tuple[str, ...]:
        v = get(key, default)
        if v is None:
            raise CampaignError(f"{path}: {where}.{key}: required (a list)")
        if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
            raise CampaignError(f"{path}: {where}.{key} = {v!r}: expected a list of names")
        if not v:
            raise CampaignError(f"{path}: {where}.{key} is empty: nothing to run")
        for s in v:
            if allowed is not None and s not in allowed:
                raise CampaignError(f"{path}: {where}.{key}: {s!r} is not one of {', '.join(allowed)}")
        if len(set(v)) != len(v):
            raise CampaignError(f"{path}: {where}.{key}: {v!r} names a value twice")
        return tuple(v)

    scenarios = tuple(_scenario_ref(path, s) for s in names("scenarios", None))
    strategies = names("strategies", tuple(STRATEGIES))
    winds = names("winds", INPROCESS_WIND_MODES, ["estimated"])
    seeds = _seeds(path, f"{where}.seeds", get("seeds"))
    limit = get("time_limit_s")
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int | float) or not 1 <= limit <= 86400):
        raise CampaignError(f"{path}: {where}.time_limit_s = {limit!r}: allowed range is [1, 86400] s")
    sfile = get("strategy_file")
    if sfile is not None:
        if not isinstance(sfile, str):
            raise CampaignError(f"{path}: {where}.strategy_file = {sfile!r}: expected a path")
        sp = Path(sfile) if Path(sfile).is_absolute() else path.parent / sfile
        if not sp.is_file():
            raise CampaignError(f"{path}: {where}.strategy_file: {sp} does not exist")
        sfile = str(sp)
    sc_params = _params(path, where, "scenario", camp.get("scenario", {}), g.get("scenario", {}))
    for name, _ in sc_params:
        try:
            check_name(name)
        except ScenarioError as e:
            raise CampaignError(f"{path}: {where}.scenario: {e}") from None
    st_params = _params(path, where, "strategy", camp.get("strategy", {}), g.get("strategy", {}))
    for name, _ in st_params:
        owner = name.split(".", 1)[0] if "." in name else None
        if owner is not None and owner not in STRATEGIES:
            raise CampaignError(f"{path}: {where}.strategy: {name!r}: {owner!r} is not a strategy "
                                f"({', '.join(STRATEGIES)}); common knobs have no prefix")  # fmt: skip
        if owner is not None and owner not in strategies:
            raise CampaignError(f"{path}: {where}.strategy: {name!r} sets a knob of {owner}, "
                                f"which this grid does not fly ({', '.join(strategies)})")  # fmt: skip
    return Grid(index, scenarios, strategies, winds, seeds, None if limit is None else float(limit),
                sfile, sc_params, st_params)  # fmt: skip


def _scenario_ref(path: Path, ref: str) -> str:
    """A built-in name as it is; a ``.toml`` path made absolute from the campaign file's folder."""
    if ref.endswith(".toml") and not Path(ref).is_absolute():
        return str((path.parent / ref).resolve())
    return ref


def _seeds(path: Path, where: str, v: Any) -> tuple[int, ...]:
    if v is None:
        raise CampaignError(f"{path}: {where}: required (a list of integers or {{ start = N, count = M }})")
    if isinstance(v, dict):
        if set(v) != {"start", "count"}:
            raise CampaignError(f"{path}: {where} = {v!r}: expected {{ start = N, count = M }}")
        start, count = v["start"], v["count"]
        if not all(isinstance(x, int) and not isinstance(x, bool) for x in (start, count)) or start < 0:
            raise CampaignError(f"{path}: {where} = {v!r}: start and count must be integers, start >= 0")
        if not 0 < count <= 1_000_000:
            raise CampaignError(f"{path}: {where}.count = {count}: must be in [1, 1000000] (0 runs nothing)")
        return tuple(range(start, start + count))
    if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in v):
        raise CampaignError(f"{path}: {where} = {v!r}: expected a list of integers >= 0 or {{ start, count }}")
    if not v:
        raise CampaignError(f"{path}: {where} is empty: nothing to run")
    if len(set(v)) != len(v):
        raise CampaignError(f"{path}: {where}: a seed is listed twice")
    return tuple(v)


def _params(path: Path, where: str, kind: str, base: Any, over: Any) -> tuple[tuple[str, tuple[Value, ...]], ...]:
    for t, w in ((base, f"campaign.{kind}"), (over, f"{where}.{kind}")):
        if not isinstance(t, dict):
            raise CampaignError(f"{path}: [{w}]: expected a table of parameters")
    merged = {**base, **over}
    return tuple((name, _values(path, f"{where}.{kind}.{name}", v)) for name, v in merged.items())


def _values(path: Path, where: str, v: Any) -> tuple[Value, ...]:
    """A scalar (one value), a list, or a range table -> the values (all of one type)."""
    if isinstance(v, dict):
        vals: list[Value] = list(_range(path, where, v))
    elif isinstance(v, list):
        vals = list(v)
        # A list of numbers is a sweep; a value that is itself a list (a vector) is given as [[...], ...].
    else:
        vals = [v]
    if not vals:
        raise CampaignError(f"{path}: {where} is empty: nothing to run")
    if len(vals) > MAX_VALUES:
        raise CampaignError(f"{path}: {where}: {len(vals)} values (at most {MAX_VALUES})")
    kinds = {"number" if isinstance(x, int | float) and not isinstance(x, bool) else type(x).__name__ for x in vals}
    if len(kinds) != 1:
        raise CampaignError(f"{path}: {where} = {v!r}: mixes types ({', '.join(sorted(kinds))}); give one type")
    if "number" in kinds and not all(math.isfinite(x) for x in vals):  # type: ignore[arg-type]
        raise CampaignError(f"{path}: {where} = {v!r}: values must be finite")
    if len({repr(x) for x in vals}) != len(vals):
        raise CampaignError(f"{path}: {where} = {v!r}: a value is listed twice")
    return tuple(vals)


def _range(path: Path, where: str, r: dict[str, Any]) -> list[float | int]:
    """``{start, stop, step}`` or ``{start, stop, num}``; ``stop`` is included (within rounding)."""
    keys = set(r)
    if keys not in ({"start", "stop", "step"}, {"start", "stop", "num"}):
        raise CampaignError(f"{path}: {where} = {r!r}: a range is {{ start, stop, step }} or {{ start, stop, num }}")
    if not all(isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in r.values()):
        raise CampaignError(f"{path}: {where} = {r!r}: range bounds must be finite numbers")
    start, stop = r["start"], r["stop"]
    if "num" in r:
        num = r["num"]
        if not isinstance(num, int) or not 1 <= num <= MAX_VALUES:
            raise CampaignError(f"{path}: {where}.num = {num!r}: must be an integer in [1, {MAX_VALUES}]")
        if num == 1:
            return [start]
        vals = [start + (stop - start) * i / (num - 1) for i in range(num)]
    else:
        step = r["step"]
        if step == 0 or (stop - start) / step < 0:
            raise CampaignError(f"{path}: {where}.step = {step!r}: must be non-zero and point from start to stop")
        n = math.floor((stop - start) / step + 1e-9) + 1
        if n > MAX_VALUES:
            raise CampaignError(f"{path}: {where}: {n} values (at most {MAX_VALUES})")
        vals = [start + i * step for i in range(n)]
    if all(isinstance(x, int) for x in (start, stop, r.get("step", 0))) and "num" not in r:
        return [int(x) for x in vals]
    return [float(f"{x:.12g}") for x in vals]  # 0.1 + 2 * 0.1 is 0.30000000000000004: keep 0.3
