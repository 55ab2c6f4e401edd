"""Strategy parameters: dataclasses with ranges, loaded from a TOML ``[strategy]`` table.

A strategy file is TOML. Keys common to every strategy sit in ``[strategy]``; keys of one
strategy in its sub-table (``[strategy.anemotaxis]``, ``[strategy.surge-cast]``,
``[strategy.zigzag]``), which may also override a common key for that strategy only::

    [strategy]
    altitude_m = 3.0              # search altitude above the start point [m]
    speed_m_s = 2.5               # ground speed while searching [m/s]
    wind_filter_cutoff_hz = 0.05  # Butterworth cutoff on the upwind direction [Hz]

    [strategy.surge-cast]
    cast_half_width_m = 4.0

Every value is checked against the range in the field's metadata; an error names the field,
the value and the allowed range. Units: SI (m, s, m/s, Hz); angles in degrees in the file.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any


class ParamError(ValueError):
    """A strategy parameter is missing, unknown or out of range (the message names it)."""


def _p(default: float, lo: float, hi: float, doc: str) -> Any:
    return field(default=default, metadata={"range": (lo, hi), "doc": doc})


@dataclass(frozen=True)
class CommonParams:
    """Parameters every strategy uses (SI units; angles in degrees)."""

    altitude_m: float = _p(3.0, 0.5, 100.0, "search altitude above the start point [m]")
    speed_m_s: float = _p(2.5, 0.2, 10.0, "ground speed while searching [m/s]")
    rate_hz: float = _p(10.0, 1.0, 50.0, "strategy tick rate the runner calls update() at [Hz]")
    wind_filter_cutoff_hz: float = _p(0.05, 0.001, 5.0, "low-pass cutoff on the upwind direction [Hz]")
    wind_filter_order: int = _p(2, 1, 8, "Butterworth order of the direction filter")
    min_wind_m_s: float = _p(0.5, 0.0, 10.0, "below this horizontal wind speed the direction is ignored [m/s]")
    wind_max_sigma_deg: float = _p(15.0, 0.1, 180.0, "wind directions less certain than this (1-sigma) are not used "
                                   "[deg]")
    wind_wait_s: float = _p(20.0, 0.0, 300.0, "after take-off, hover up to this long for a usable wind direction [s]")
    lost_s: float = _p(2.0, 0.1, 60.0, "time without detection after which the plume counts as lost [s]")
    declare_after_s: float = _p(60.0, 0.5, 300.0, "time lost after a verified end at the most-upwind hit "
                                 "before declaring it anyway [s]")
    overshoot_m: float = _p(4.0, 0.0, 50.0, "how far upwind of the most-upwind detection the vehicle must "
                            "have searched before declaring [m]")
    sensor_tau_s: float = _p(0.5, 0.01, 30.0, "chemical sensor time constant (its datasheet) [s]")
    sensor_noise_mg_m3: float = _p(0.01, 0.0, 100.0, "chemical sensor noise, 1-sigma [mg/m^3]")
    sensor_lag_s: float = _p(0.3, 0.0, 10.0, "chemical sensor lag: a detection is attributed to the position "
                             "this long before it arrived [s]")
    candidate_min_mg_m3: float = _p(0.2, 0.0, 1e6, "weakest hit that can be the declared source [mg/m^3] "
                                    "(a hit that interrupts a verification sweep always can)")
    confirmations: int = _p(2, 1, 10, "verified ends (a crosswind sweep upwind of the most-upwind hit that found "
                            "nothing) at the same place needed to declare")
    verify_offset_m: float = _p(3.0, 0.5, 30.0, "the verification sweep flies this far upwind of the most-upwind "
                                "hit [m]")
    verify_half_width_m: float = _p(4.0, 0.5, 50.0, "half-width of the verification sweep about the most-upwind hit, "
                                    "crosswind, before widening by the wind direction uncertainty [m]")
    verify_margin_m: float = _p(2.0, 0.0, 50.0, "the verification sweep covers half the crosswind spread of the "
                                "recent hits plus this margin on each side, if wider than verify_half_width_m [m]")
    verify_speed_m_s: float = _p(2.5, 0.2, 10.0, "ground speed of the verification sweep [m/s]")
    verify_legs: int = _p(2, 1, 20, "crosswind legs of one verification sweep")
    verify_growth: float = _p(1.0, 1.0, 5.0, "half-width factor of each further verification at the same place")
    min_hits_near: int = _p(12, 0, 1000, "hits within 5 m of the most-upwind hit needed before it can be declared "
                            "(the plume just downwind of a source is continuous)")
    min_followed_m: float = _p(10.0, 0.0, 1000.0, "the hits must reach at least this far downwind of the declared "
                               "point (the plume leading to it was followed) [m]")
    verify_max_half_width_m: float = _p(12.0, 0.5, 100.0, "largest verification half-width [m]")
    memory_s: float = _p(20.0, 1.0, 600.0, "time window of detections used for the plume centreline [s]")
    centerline_gain: float = _p(0.4, 0.0, 5.0, "lateral velocity per metre off the estimated centreline [1/s]")
    descend_altitude_m: float = _p(1.5, 0.3, 100.0, "altitude of the final descent over the declared source [m]")
    descend_hold_s: float = _p(2.0, 0.0, 60.0, "time spent over the declared source before stopping [s]")
    initial_heading_deg: float = _p(math.nan, -360.0, 360.0, "initial search heading without wind information "
                                    "[deg, 0 = north]; NaN: drawn from the trial seed")


@dataclass(frozen=True)
class AnemotaxisParams(CommonParams):
    """Anemotaxis (paper Figs. 16-18): fly upwind on the filtered wind direction."""

    speed_m_s: float = _p(2.0, 0.2, 10.0, "ground speed upwind [m/s]")
    declare_after_s: float = _p(8.0, 0.5, 300.0, "time without detection, upwind of the best point, before "
                                "declaring [s] (no casting: a lost plume is not searched for)")
    confirmations: int = _p(1, 1, 10, "verified ends at the same place needed to declare (anemotaxis has no "
                            "lost search to re-acquire the plume between verifications)")


@dataclass(frozen=True)
class SurgeCastParams(CommonParams):
    """Silkworm moth surge-cast."""

    surge_persist_s: float = _p(3.0, 0.0, 30.0, "keep surging this long after the last detection [s]")
    confirmations: int = _p(1, 1, 10, "verified ends at the same place needed to declare: one for surge-cast (its "
                            "surges follow the plume to the end and its slow verification waits out a meander; a "
                            "second costs ~0.6x the start distance of path; in high turbulence 2 is safer, see "
                            "benchmarks/search_tradeoff.py)")
    verify_speed_m_s: float = _p(1.0, 0.2, 10.0, "ground speed of the verification sweep [m/s]: slow, because "
                                 "what a verification waits for is time (a meandering plume from further "
                                 "upwind swings back within seconds), not distance")
    cast_half_width_m: float = _p(4.0, 0.5, 100.0, "first cast half-amplitude, crosswind [m]")
    cast_growth: float = _p(1.5, 1.0, 5.0, "cast amplitude factor after each full sweep")
    cast_max_half_width_m: float = _p(30.0, 1.0, 500.0, "largest cast half-amplitude [m]")
    cast_drift_m_s: float = _p(0.3, 0.0, 5.0, "downwind drift of the cast anchor [m/s]")
    cast_back_m: float = _p(1.0, -20.0, 50.0, "cast anchor: this far downwind of the last detection [m]")
    lost_s: float = _p(1.5, 0.1, 60.0, "time without detection after which the plume counts as lost (and, "
                       "upwind of the most-upwind hit, the verification sweep starts) [s]")


@dataclass(frozen=True)
class ZigzagParams(CommonParams):
    """Dung-beetle zig-zag."""

    angle_deg: float = _p(30.0, 5.0, 85.0, "leg angle off the upwind direction [deg] (30: each metre upwind costs "
                          "1.15 m of leg, 45 costs 1.41; development seeds 100-179: 78 / 80 at 3.7-4.0x with 30 "
                          "and slow verification vs 75 / 80 at 5.1x with 45 and 2.5 m/s sweeps)")
    lost_s: float = _p(3.0, 0.1, 60.0, "time without detection (after edge_s) after which the plume counts as lost "
                       "[s]; the legs leave the plume by design, so longer than for surge-cast")
    overshoot_m: float = _p(6.0, 0.0, 50.0, "how far upwind of the most-upwind hit the vehicle must have searched "
                            "before declaring [m]")
    edge_s: float = _p(1.0, 0.1, 30.0, "time without detection in a leg that marks the plume edge [s]")
    leg_max_half_width_m: float = _p(12.0, 1.0, 200.0, "turn back this far off the centreline anyway [m]")
    lost_half_width_m: float = _p(6.0, 0.5, 200.0, "first sweep half-width once the plume is lost [m]")
    lost_growth: float = _p(1.5, 1.0, 5.0, "sweep width factor after each lost sweep")
    lost_max_half_width_m: float = _p(30.0, 1.0, 500.0, "largest lost sweep half-width [m]")
    lost_drift_m_s: float = _p(0.3, 0.0, 5.0, "downwind drift of the lost sweep anchor [m/s]")
    lost_back_m: float = _p(1.0, -20.0, 50.0, "lost sweep anchor: this far downwind of the last detection [m]")
    verify_speed_m_s: float = _p(1.0, 0.2, 10.0, "ground speed of the verification sweep [m/s]: slow, as "
                                 "surge-cast's (a verification waits for a meander to swing back; since the sweeps "
                                 "turn about a world point, slow sweeps no longer cost zig-zag success)")


#: Fields where NaN means "not set" (documented per field).
NAN_ALLOWED = frozenset({"initial_heading_deg"})

PARAM_CLASSES: dict[str, type[CommonParams]] = {
    "anemotaxis": AnemotaxisParams,
    "surge-cast": SurgeCastParams,
    "zigzag": ZigzagParams,
}


def _check(cls_name: str, name: str, value: Any, lo: float, hi: float, integer: bool) -> float | int:
    where = f"strategy.{cls_name}.{name}" if cls_name else f"strategy.{name}"
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParamError(f"{where} = {value!r}: expected a number in [{lo}, {hi}]")
    if integer and (not float(value).is_integer()):
        raise ParamError(f"{where} = {value!r}: expected an integer in [{lo}, {hi}]")
    if math.isnan(value) and name in NAN_ALLOWED:
        return float(value)
    if not (lo <= value <= hi):
        raise ParamError(f"{where} = {value!r}: allowed range is [{lo}, {hi}]")
    return int(value) if integer else float(value)


def validate(params: CommonParams, strategy: str = "") -> CommonParams:
    """Check every field of ``params`` against its range (ParamError naming the field)."""
    for f in fields(params):
        lo, hi = f.metadata["range"]
        v = getattr(params, f.name)
        _check(strategy, f.name, v, lo, hi, isinstance(f.default, int) and not isinstance(f.default, bool))
    if params.descend_altitude_m > params.altitude_m:
        raise ParamError(
            f"strategy.descend_altitude_m = {params.descend_altitude_m}: must not exceed "
            f"strategy.altitude_m = {params.altitude_m}"
        )
    if params.wind_filter_cutoff_hz >= params.rate_hz / 2.0:
        raise ParamError(
            f"strategy.wind_filter_cutoff_hz = {params.wind_filter_cutoff_hz}: must be below "
            f"rate_hz / 2 = {params.rate_hz / 2.0}"
        )
    return params


def params_from_table(strategy: str, table: dict[str, Any] | None) -> CommonParams:
    """Parameters of ``strategy`` from a parsed ``[strategy]`` table (None: defaults)."""
    if strategy not in PARAM_CLASSES:
        raise ParamError(f"unknown strategy {strategy!r}: choose one of {', '.join(PARAM_CLASSES)}")
    cls = PARAM_CLASSES[strategy]
    table = dict(table or {})
    known = {f.name for f in fields(cls)}
    common = {f.name for f in fields(CommonParams)}
    values: dict[str, Any] = {}
    for key, v in table.items():
        if key in PARAM_CLASSES:
            if not isinstance(v, dict):
                raise ParamError(f"strategy.{key}: expected a table")
            continue
        if key not in common:
            raise ParamError(
                f"strategy.{key}: unknown common parameter (strategy-specific keys go in "
                f"[strategy.<name>]); common keys: {', '.join(sorted(common))}"
            )
        values[key] = v
    sub = table.get(strategy, {})
    for key, v in sub.items():
        if key not in known:
            raise ParamError(f"strategy.{strategy}.{key}: unknown parameter; allowed: {', '.join(sorted(known))}")
        values[key] = v
    p = cls()
    for key, v in values.items():
        f = next(f for f in fields(cls) if f.name == key)
        lo, hi = f.metadata["range"]
        where = strategy if key in sub else ""
        values[key] = _check(where, key, v, lo, hi, isinstance(f.default, int) and not isinstance(f.default, bool))
    return validate(replace(p, **values), strategy)


def load_params(strategy: str, path: str | Path | None = None) -> CommonParams:
    """Parameters of ``strategy`` from a strategy file's ``[strategy]`` table (None: defaults)."""
    if path is None:
        return params_from_table(strategy, None)
    p = Path(path)
    if not p.is_file():
        raise ParamError(f"strategy file {p} does not exist")
    try:
        data = tomllib.loads(p.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as e:
        raise ParamError(f"{p}: not a TOML text file (byte {e.start} is not UTF-8)") from None
    except tomllib.TOMLDecodeError as e:
        raise ParamError(f"{p}: TOML syntax error: {e}") from None
    unknown = set(data) - {"strategy"}
    if unknown:
        raise ParamError(f"{p}: unknown top-level keys {sorted(unknown)}; parameters go in [strategy]")
    tbl = data.get("strategy", {})
    if not isinstance(tbl, dict):
        raise ParamError(f"{p}: [strategy] must be a table")
    return params_from_table(strategy, tbl)
