"""A campaign's grids -> its missions (:class:`~mission.campaign.task.Task`), every value validated first.

Each distinct scenario variant (base scenario + scenario parameters) is built from the base TOML
table and parsed by :func:`sitl.scenario.parse_scenario`; each distinct strategy parameter set goes
through :func:`mission.strategies.params.params_from_table`. A bad value is one
:class:`~mission.campaign.spec.CampaignError` naming the grid, the parameter and the field, before
any mission runs. A strategy knob of another strategy does not multiply a strategy's missions
(``surge-cast.cast_half_width_m`` = 3 values gives zig-zag its missions once); missions that come
out identical (same key) in two grids are flown once.
"""

from __future__ import annotations

import itertools
import tomllib
from dataclasses import asdict
from pathlib import Path
from typing import Any

from mission.campaign.scenario_params import apply
from mission.campaign.spec import CampaignError, CampaignSpec, Grid
from mission.campaign.task import Task, config_hash, task_key
from mission.strategies.params import ParamError, params_from_table
from sitl.parsing import ScenarioError
from sitl.scenario import parse_scenario, scenario_table


def expand(spec: CampaignSpec) -> list[Task]:
    """Every mission of the campaign, in grid order, each key once (validates every configuration)."""
    tasks: dict[str, Task] = {}
    bases: dict[str, dict[str, Any]] = {}
    for grid in spec.grids:
        for task in _grid_tasks(spec, grid, bases):
            tasks.setdefault(task.key, task)
    if not tasks:
        raise CampaignError(f"{spec.path}: the grid is empty: nothing to run")
    return list(tasks.values())


def _combos(params: tuple[tuple[str, tuple[Any, ...]], ...]) -> list[dict[str, Any]]:
    names = [n for n, _ in params]
    return [dict(zip(names, vals, strict=True)) for vals in itertools.product(*(v for _, v in params))]


def _grid_tasks(spec: CampaignSpec, grid: Grid, bases: dict[str, dict[str, Any]]) -> list[Task]:
    where = f"{spec.path}: grid[{grid.index}]"
    variants = []  # (scenario, its parameters, the resolved table)
    for sc in grid.scenarios:
        if sc not in bases:
            try:
                bases[sc] = scenario_table(sc)[0]
            except ScenarioError as e:
                raise CampaignError(f"{where}: {e}") from None
        for combo in _combos(grid.scenario_params):
            variants.append((sc, combo, _scenario_variant(where, sc, bases[sc], combo)))
    base_strategy = _strategy_file_table(where, grid.strategy_file)
    out = []
    for strategy in grid.strategies:
        mine = tuple((n, v) for n, v in grid.strategy_params if "." not in n or n.split(".", 1)[0] == strategy)
        for knobs in _combos(mine):
            table = _strategy_table(base_strategy, strategy, knobs)
            try:
                resolved = asdict(params_from_table(strategy, table))
            except ParamError as e:
                shown = ", ".join(f"{k} = {v!r}" for k, v in knobs.items()) or "defaults"
                raise CampaignError(f"{where}: {strategy} with {shown}: {e}") from None
            for (sc, sc_params, sc_table), wind, seed in itertools.product(variants, grid.winds, grid.seeds):
                key = task_key(sc, sc_params, strategy, knobs, grid.strategy_file, wind, seed, grid.time_limit_s,
                               spec.geofence_m)  # fmt: skip
                out.append(Task(key=key, campaign=spec.name, grid=grid.index, scenario=sc, scenario_table=sc_table,
                                strategy=strategy, strategy_table=table, wind=wind, seed=seed,
                                time_limit_s=grid.time_limit_s, geofence_m=spec.geofence_m,
                                params={**sc_params, **knobs},
                                config_hash=config_hash(sc_table, resolved)))  # fmt: skip
    return out


def _scenario_variant(where: str, sc: str, base: dict[str, Any], combo: dict[str, Any]) -> dict[str, Any]:
    shown = ", ".join(f"{k} = {v!r}" for k, v in combo.items())
    try:
        table = apply(base, combo)
        scenario = parse_scenario(table, sc)
    except ScenarioError as e:
        raise CampaignError(f"{where}: scenario {Path(sc).name}{' with ' + shown if shown else ''}: {e}") from None
    if scenario.plume is None:
        raise CampaignError(f"{where}: scenario {Path(sc).name} has no [plume] table: nothing to search for")
    return table


def _strategy_file_table(where: str, path: str | None) -> dict[str, Any]:
    if path is None:
        return {}
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise CampaignError(f"{where}: strategy_file {path}: {e}") from None
    if set(data) - {"strategy"} or not isinstance(data.get("strategy", {}), dict):
        raise CampaignError(f"{where}: strategy_file {path}: expected only a [strategy] table")
    return dict(data.get("strategy", {}))


def _strategy_table(base: dict[str, Any], strategy: str, knobs: dict[str, Any]) -> dict[str, Any]:
    """The ``[strategy]`` table: the base file's, with the knobs set (``name`` common, ``strategy.name`` own)."""
    table = {k: (dict(v) if isinstance(v, dict) else v) for k, v in base.items()}
    for name, value in knobs.items():
        if "." in name:
            table.setdefault(strategy, {})[name.split(".", 1)[1]] = value
        else:
            table[name] = value
    return table
