"""Checks shared by every configuration table (scenario, plume, vehicle overrides).

Every error is a :class:`ScenarioError` whose message names the field and the allowed values,
the same way everywhere: ``wind.speed_m_s = -3: allowed range is [0.0, 100.0]``.
"""

from __future__ import annotations

import math
from typing import Any


class ScenarioError(ValueError):
    """A scenario file or value is invalid; the message names the field."""


def number(name: str, value: Any, lo: float, hi: float) -> float:
    """A finite number in [lo, hi] (bools are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f"{name}: expected a number in [{lo}, {hi}], got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise ScenarioError(f"{name} = {value!r}: allowed range is [{lo}, {hi}]")
    return v


def vec3(name: str, value: Any, lim: float = 1e5) -> tuple[float, float, float]:
    """Three numbers [north, east, down], each within +-lim."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ScenarioError(f"{name}: expected 3 numbers [north, east, down], got {value!r}")
    a, b, c = (number(f"{name}[{i}]", v, -lim, lim) for i, v in enumerate(value))
    return (a, b, c)


def table(name: str, value: Any, allowed: set[str] | frozenset[str]) -> dict[str, Any]:
    """A TOML table with only the allowed keys."""
    if not isinstance(value, dict):
        raise ScenarioError(f"[{name}]: expected a table, got {value!r}")
    unknown = set(value) - allowed
    if unknown:
        raise ScenarioError(
            f"[{name}]: unknown key(s) {', '.join(sorted(unknown))}; allowed: {', '.join(sorted(allowed))}"
        )
    return value


def boolean(name: str, value: Any) -> bool:
    """true or false."""
    if not isinstance(value, bool):
        raise ScenarioError(f"{name}: expected true or false, got {value!r}")
    return value


def choice(name: str, value: Any, allowed: tuple[str, ...], hint: str = "") -> str:
    """One of the allowed strings."""
    if value not in allowed:
        raise ScenarioError(f"{name} = {value!r}: allowed values are {hint or ', '.join(map(repr, allowed))}")
    return str(value)
