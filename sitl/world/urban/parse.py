"""Build an :class:`~.config.UrbanScene` from plain data (a parsed TOML table), naming bad fields.

The table layout (what a scenario file's ``[urban]`` table would hold)::

    [urban.wind]      speed_m_s = 7.0, from_deg = 45.0, reference_height_m = 10.0, ...
    [urban.grid]      x_min_m = 0, y_min_m = 0, length_x_m = 400, length_y_m = 400, height_m = 60, spacing_m = 2
    [urban.options]   rooftop = true, ...                              (optional)
    [[urban.buildings]] type = "box", x_m = 200, y_m = 150, length_m = 30, width_m = 20, height_m = 15
    [[urban.buildings]] type = "polygon", vertices_m = [[0, 0], [10, 0], [0, 10]], height_m = 8

Errors are :class:`~.config.ConfigError` with the full path: ``buildings[2].height_m = -3.0: must
be > 0 (m)``; unknown keys are errors too (a typo must not silently fall back to a default).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from urbanflow.config import (
    BoxBuilding,
    Building,
    ConfigError,
    GridSpec,
    LogWindProfile,
    PolygonBuilding,
    UrbanOptions,
    UrbanScene,
)

_BUILDING_TYPES: dict[str, type] = {"box": BoxBuilding, "polygon": PolygonBuilding}


def _build(path: str, cls: type, data: Any, skip: tuple[str, ...] = ()) -> Any:
    """``cls(**data)`` with unknown / missing keys and field errors reported under ``path``."""
    if not isinstance(data, Mapping):
        raise ConfigError(path, data, f"must be a table of {cls.__name__} fields")
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names - set(skip))
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}", data[unknown[0]], f"unknown key; allowed: {', '.join(sorted(names))}")
    required = [
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    missing = [n for n in required if n not in data]
    if missing:
        raise ConfigError(f"{path}.{missing[0]}", None, "is required")
    kwargs = {k: v for k, v in data.items() if k not in skip}
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        raise exc.prefixed(path) from None


def parse_building(path: str, data: Any) -> Building:
    """One building table (``type = "box"`` or ``"polygon"``) as a config dataclass."""
    if not isinstance(data, Mapping):
        raise ConfigError(path, data, "must be a table with type = 'box' or 'polygon'")
    kind = data.get("type", "box")
    if kind not in _BUILDING_TYPES:
        raise ConfigError(f"{path}.type", kind, f"must be one of {sorted(_BUILDING_TYPES)}")
    if kind == "polygon" and "vertices_m" in data:
        data = {**data, "vertices_m": tuple(tuple(v) if isinstance(v, list | tuple) else v for v in data["vertices_m"])}
    return _build(path, _BUILDING_TYPES[kind], data, skip=("type",))


def parse_urban_scene(data: Mapping[str, Any], name: str = "") -> UrbanScene:
    """A validated :class:`UrbanScene` from a table with ``buildings``, ``wind``, ``grid``, ``options``."""
    allowed = {"buildings", "wind", "grid", "options"}
    if not isinstance(data, Mapping):
        raise ConfigError("urban", data, "must be a table")
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ConfigError(unknown[0], data[unknown[0]], f"unknown key; allowed: {', '.join(sorted(allowed))}")
    raw = data.get("buildings", [])
    if not isinstance(raw, list | tuple):
        raise ConfigError("buildings", raw, "must be a list of building tables")
    buildings = tuple(parse_building(f"buildings[{i}]", b) for i, b in enumerate(raw))
    if "grid" not in data:
        raise ConfigError("grid", None, "is required")
    wind = _build("wind", LogWindProfile, data.get("wind", {}))
    grid = _build("grid", GridSpec, data["grid"])
    options = _build("options", UrbanOptions, data.get("options", {}))
    return UrbanScene(buildings=buildings, wind=wind, grid=grid, options=options, name=name)
