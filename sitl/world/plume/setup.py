"""The scenario's ``[plume]`` table, parsed once into a :class:`PlumeSetup` (``Scenario.plume``).

Every error names the field and the allowed values (a bad file fails at load time). The
world builds its plume and chemical sensor from the setup (:mod:`sitl.world.plume.part`).

TOML format (every key optional except ``sources``; defaults shown)::

    [plume]
    model = "puff"              # "puff" (instantaneous, Farrell) | "gaussian" (time-averaged)
    stability = "D"             # Pasquill-Gifford class "A" (very unstable) .. "F" (stable)
    puff_rate_hz = 10.0         # puffs released per second per source [Hz]
    max_puffs = 1000            # cap on live puffs (oldest removed first)
    update_rate_hz = 10.0       # plume integration rate [Hz]; must divide the mode rate
    warmup_s = 120.0            # plume formed before t = 0 [s] (built at t0 = -warmup_s)
    source_radius_m = 0.3       # initial puff standard deviation [m]
    min_wind_speed_m_s = 0.5    # wind-speed floor for dilution [m/s]
    subtract_wind_turbulence = true
    # domain_min_ned = [-100.0, -100.0, -50.0]   # optional box [m, NED]; both or neither
    # domain_max_ned = [400.0, 100.0, 0.0]
    sources = [{ position_ned = [60.0, 0.0, -2.0], rate_g_s = 1.0 }]
    #   per source: position_ned [m, NED, z <= 0], rate_g_s [g/s] (>= 0),
    #   start_s [s] (default -warmup_s: emitting since the warm-up began; start_s = 0
    #   switches the source on at t = 0, so the warm-up forms no plume), stop_s [s] (optional)

    [plume.sensor]              # sitl.world.chem_sensor.ChemSensorConfig fields
    time_constant_s = 0.5       # [s]
    noise_std_mg_m3 = 0.01      # [mg/m^3]
    detection_limit_mg_m3 = 0.05
    saturation_mg_m3 = 1000.0
    sample_rate_hz = 10.0       # [Hz]; must divide the mode rate
    initial_mg_m3 = 0.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from sitl.parsing import ScenarioError, choice, number, table, vec3
from sitl.world.chem_sensor import ChemSensorConfig
from sitl.world.plume.config import PLUME_MODELS, STABILITY_CLASSES, PlumeConfig, Source

PLUME_KEYS: frozenset[str] = frozenset(
    {
        "model", "stability", "puff_rate_hz", "max_puffs", "update_rate_hz", "warmup_s", "sources",
        "domain_min_ned", "domain_max_ned", "source_radius_m", "min_wind_speed_m_s",
        "subtract_wind_turbulence", "sensor",
    }
)  # fmt: skip
SOURCE_KEYS: frozenset[str] = frozenset({"position_ned", "rate_g_s", "start_s", "stop_s"})
SENSOR_KEYS: frozenset[str] = frozenset(f.name for f in fields(ChemSensorConfig))


@dataclass(frozen=True)
class PlumeSetup:
    """A parsed ``[plume]`` table.

    plume: plume model configuration (source times in simulation seconds).
    sensor: chemical sensor configuration.
    warmup_s: how long the plume is integrated before t = 0 [s].
    """

    plume: PlumeConfig
    sensor: ChemSensorConfig
    warmup_s: float


def _divisor_rate(name: str, value: Any, mode_rate_hz: float) -> float:
    """A rate [Hz] that divides the mode rate exactly (see module docstring, Timing)."""
    rate = number(name, value, 1e-3, mode_rate_hz)
    n = mode_rate_hz / rate
    if abs(n - round(n)) > 1e-6:
        examples = ", ".join(f"{mode_rate_hz / k:g}" for k in (1, 2, 5, 10, 25, 50) if mode_rate_hz / k >= 1e-3)
        raise ScenarioError(
            f"{name} = {value!r}: must divide the {mode_rate_hz:g} Hz mode rate; allowed values are "
            f"{mode_rate_hz:g}/n Hz for integer n >= 1 (e.g. {examples})"
        )
    return rate


def _parse_source(name: str, value: Any, warmup_s: float) -> Source:
    tbl = table(name, value, SOURCE_KEYS)
    for key in ("position_ned", "rate_g_s"):
        if key not in tbl:
            raise ScenarioError(f"{name}.{key}: required")
    pos = vec3(f"{name}.position_ned", tbl["position_ned"])
    if pos[2] > 0.0:
        raise ScenarioError(f"{name}.position_ned[2] = {pos[2]}: must be <= 0 (NED: the ground is z = 0)")
    rate = number(f"{name}.rate_g_s", tbl["rate_g_s"], 0.0, 1e6)
    start = number(f"{name}.start_s", tbl.get("start_s", -warmup_s), -1e6, 1e6)
    stop = math.inf
    if "stop_s" in tbl:
        stop = number(f"{name}.stop_s", tbl["stop_s"], -1e6, 1e6)
        if stop <= start:
            raise ScenarioError(f"{name}.stop_s = {stop}: must be > start_s = {start}")
    return Source(pos, rate, start, stop)


def parse_plume_table(tbl: Any, mode_rate_hz: float = 50.0) -> PlumeSetup:
    """Parse and validate a raw ``[plume]`` table (see the module docstring for the format).

    tbl: the table as read from TOML (dict).
    mode_rate_hz: the simulation's mode-tick rate [Hz]; plume and sensor rates must divide it.

    Raises ``sitl.scenario.ScenarioError`` naming the field (``plume.<key>``) and the
    allowed values.
    """
    tbl = table("plume", tbl, PLUME_KEYS)
    model = choice("plume.model", tbl.get("model", "puff"), PLUME_MODELS, ", ".join(repr(m) for m in PLUME_MODELS))
    stability = choice(
        "plume.stability", tbl.get("stability", "D"), STABILITY_CLASSES,
        f"{STABILITY_CLASSES[0]}-{STABILITY_CLASSES[-1]} (Pasquill-Gifford)",
    )  # fmt: skip
    warmup = number("plume.warmup_s", tbl.get("warmup_s", 120.0), 0.0, 3600.0)
    max_puffs = tbl.get("max_puffs", 1000)
    if isinstance(max_puffs, bool) or not isinstance(max_puffs, int) or not 1 <= max_puffs <= 1_000_000:
        raise ScenarioError(f"plume.max_puffs = {max_puffs!r}: allowed values are integers in [1, 1000000]")
    raw_sources = tbl.get("sources")
    if not isinstance(raw_sources, list) or not raw_sources:
        raise ScenarioError(
            "plume.sources: required, a non-empty list of "
            "{ position_ned = [n, e, d], rate_g_s = ..., start_s = ..., stop_s = ... } tables"
        )
    sources = tuple(_parse_source(f"plume.sources[{i}]", s, warmup) for i, s in enumerate(raw_sources))
    dom_lo = vec3("plume.domain_min_ned", tbl["domain_min_ned"]) if "domain_min_ned" in tbl else None
    dom_hi = vec3("plume.domain_max_ned", tbl["domain_max_ned"]) if "domain_max_ned" in tbl else None
    subtract = tbl.get("subtract_wind_turbulence", True)
    if not isinstance(subtract, bool):
        raise ScenarioError(f"plume.subtract_wind_turbulence = {subtract!r}: allowed values are true, false")
    plume = PlumeConfig(
        sources=sources,
        stability=stability,
        model=model,
        puff_rate_hz=number("plume.puff_rate_hz", tbl.get("puff_rate_hz", 10.0), 1e-3, 1e4),
        max_puffs=max_puffs,
        update_rate_hz=_divisor_rate("plume.update_rate_hz", tbl.get("update_rate_hz", 10.0), mode_rate_hz),
        domain_min_ned=dom_lo,
        domain_max_ned=dom_hi,
        source_radius_m=number("plume.source_radius_m", tbl.get("source_radius_m", 0.3), 1e-3, 100.0),
        min_wind_speed_m_s=number("plume.min_wind_speed_m_s", tbl.get("min_wind_speed_m_s", 0.5), 1e-3, 100.0),
        subtract_wind_turbulence=subtract,
    )
    errors = plume.validate()
    if errors:  # what the per-key checks above cannot see (e.g. domain min >= max)
        raise ScenarioError("; ".join(f"plume.{e}" for e in errors))

    raw_sensor = table("plume.sensor", tbl.get("sensor", {}), SENSOR_KEYS)
    kw: dict[str, float] = {}
    for key, value in raw_sensor.items():
        if key == "sample_rate_hz":
            kw[key] = _divisor_rate("plume.sensor.sample_rate_hz", value, mode_rate_hz)
        else:
            kw[key] = number(f"plume.sensor.{key}", value, -1e9, 1e9)
    sensor = ChemSensorConfig(**kw)
    errors = sensor.validate()
    if errors:
        raise ScenarioError("; ".join(f"plume.sensor.{e}" for e in errors))
    return PlumeSetup(plume=plume, sensor=sensor, warmup_s=warmup)


