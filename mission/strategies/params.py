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


def _c(default: str, choices: tuple[str, ...], doc: str) -> Any:
    """A field whose value is one of ``choices`` (a string in the file)."""
    return field(default=default, metadata={"choices": choices, "doc": doc})


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
    declare_after_s: float = _p(8.0, 0.5, 300.0, "time lost after a verified end at a supported candidate before "
                                "declaring it anyway [s]")
    confirmations: int = _p(1, 1, 10, "verified ends at the same place needed to declare")
    recover_half_width_m: float = _p(4.0, 0.5, 100.0, "lost-plume recovery: first cast half-width, crosswind [m]")
    recover_growth: float = _p(1.5, 1.0, 5.0, "lost-plume recovery: half-width factor after each full sweep")
    recover_max_half_width_m: float = _p(25.0, 1.0, 500.0, "lost-plume recovery: largest half-width [m]")
    recover_drift_m_s: float = _p(0.5, 0.0, 5.0, "lost-plume recovery: downwind drift of the cast [m/s]")
    recover_back_m: float = _p(2.0, -20.0, 50.0, "lost-plume recovery: the cast starts this far downwind of the "
                               "last hit [m]")
    give_up_s: float = _p(60.0, 1.0, 3600.0, "give up (nothing declared) after this long without a detection [s]")
    max_range_m: float = _p(200.0, 5.0, 5000.0, "give up when this far from home without any detection [m]")


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


@dataclass(frozen=True)
class InfotaxisParams(CommonParams):
    """Bayesian source-term estimation with information-driven moves (``mission.strategies.infotaxis``)."""

    altitude_m: float = _p(2.0, 0.5, 100.0, "search altitude above the start point [m]: the middle of the "
                           "source-height prior (at one altitude, a source below or above it looks the same as a "
                           "stronger one further upwind; at the source's height the plume starts at the source)")
    n_particles: int = _p(4000, 100, 200000, "particles of the source posterior")
    rejuvenate: float = _p(0.02, 0.0, 0.5, "share of the particles redrawn from the prior about the posterior "
                           "mean at every resampling (a lost region can come back)")
    rejuvenate_weighed: int = _p(1, 0, 1, "1: a redrawn particle enters with its likelihood of every reading so far "
                                 "(relative to the typical particle's, at most 1); 0: with the resampled weight")
    rejuvenate_along_m: float = _p(25.0, 0.0, 500.0, "rejuvenation corridor: this far up- and downwind [m]")
    rejuvenate_across_m: float = _p(8.0, 0.0, 500.0, "rejuvenation corridor: this far either side [m]")
    tempering: float = _p(0.8, 0.01, 1.0, "exponent on each bin's likelihood: consecutive bins of a first-order "
                          "sensor in an intermittent plume are correlated, not independent (1: the fitted "
                          "model's posterior was over-confident, its 90 % region held the source in 77 % of "
                          "development trials; 0.8: 90 %)")
    stability: str = _c("D", ("A", "B", "C", "D", "E", "F"), "Pasquill-Gifford class of the plume model")
    spread_reference_deg: float = _p(12.0, 0.0, 180.0, "the model holds while the wind estimate's direction "
                                     "spread (circular std over spread_tau_s) is at most this [deg]; above, the "
                                     "likelihood widens by the ratio f (0: never; 10 and 15 were tried)")
    spread_tau_s: float = _p(15.0, 1.0, 600.0, "time constant of the direction spread [s]")
    spread_tempering_power: float = _p(1.0, 0.0, 4.0, "tempering divided by f to this power")
    spread_meander_power: float = _p(1.0, 0.0, 4.0, "meander direction sigma times f to this power")
    bin_s: float = _p(0.5, 0.05, 10.0, "readings are grouped into bins this long; a bin is a hit if any reading "
                      "in it is one (hits come in bursts) [s]")
    persistence_s: float = _p(0.7, 0.01, 60.0, "correlation time of being inside the intermittent plume (hits "
                              "come in bursts, gaps last) [s]")
    intermittency_length_m: float = _p(35.0, 1.0, 1000.0, "share of time a sensor in the plume detects: "
                                       "1 / (1 + x / L) at x m downwind [m]")
    meander_fraction: float = _p(0.35, 0.0, 0.99, "share of the class's crosswind variance that is meander")
    meander_deg: float = _p(6.2, 0.0, 60.0, "plume direction meander, 1-sigma, on top of the class [deg]")
    meander_window_s: float = _p(8.0, 0.1, 600.0, "readings within this time share one meander state [s]")
    meander_nodes: int = _p(7, 1, 21, "quadrature nodes of the meander random effect")
    detection_limit_mg_m3: float = _p(0.05, 1e-6, 1e6, "the sensor's detection limit [mg/m^3]")
    false_alarm: float = _p(0.01, 1e-6, 0.2, "floor of P(hit) and P(miss) for any hypothesis (model error)")
    source_radius_m: float = _p(0.44, 0.01, 10.0, "source size of the plume model [m] (fitted with the "
                            "intermittency and meander, benchmarks/infotaxis_detection_model.py)")
    upwind_reach_m: float = _p(1.0, 0.05, 20.0, "hits can be placed this far (1-sigma) upwind of the source: the "
                               "puffs' size, navigation noise, a bin's length [m]")
    source_height_min_m: float = _p(1.0, 0.0, 50.0, "prior of the source height: lowest [m above ground]")
    source_height_max_m: float = _p(3.0, 0.0, 50.0, "prior of the source height: highest [m above ground]")
    release_min_g_s: float = _p(0.01, 1e-6, 1e6, "prior of the (effective) release rate, log-uniform: lowest [g/s]")
    release_max_g_s: float = _p(100.0, 1e-6, 1e6, "prior of the (effective) release rate: highest [g/s]")
    direction_sigma_deg: float = _p(5.0, 0.0, 90.0, "prior sigma of the plume direction about the filtered wind "
                                    "direction [deg]")
    assumed_wind_m_s: float = _p(3.0, 0.5, 30.0, "wind speed the model assumes without wind information [m/s]")
    prior_range_m: float = _p(200.0, 5.0, 2000.0, "prior box: up to this far upwind of the first position [m]")
    prior_back_m: float = _p(10.0, 0.0, 500.0, "prior box: from this far downwind of the first position [m]")
    prior_half_width_m: float = _p(80.0, 1.0, 2000.0, "prior box: this far either side crosswind [m]")
    near_m: float = _p(10.0, 0.0, 1000.0, "fly at near_speed_m_s once the posterior mean is this close and the "
                       "credible radius this small [m]")
    near_speed_m_s: float = _p(1.0, 0.2, 10.0, "ground speed near the source [m/s]")
    max_range_m: float = _p(200.0, 5.0, 5000.0, "moves stay within this horizontal distance of home [m]")
    plan_particles: int = _p(300, 10, 100000, "particles (resampled) the move choice evaluates")
    plan_directions: int = _p(16, 4, 64, "candidate headings of a move")
    plan_horizon_m: float = _p(60.0, 1.0, 200.0, "longest candidate move [m] (far from the source the "
                           "information within 20 m is flat: the vehicle wandered near the start)")
    plan_min_m: float = _p(3.0, 0.5, 200.0, "shortest candidate move [m] (moves reach the posterior: distance "
                           "to its mean plus its credible radius, within these bounds)")
    plan_points: int = _p(10, 1, 20, "readings predicted along a candidate move")
    jitter: float = _p(0.1, 0.0, 1.0, "kernel width after resampling, times the posterior spread per dimension")
    credible_level: float = _p(0.9, 0.5, 0.999, "probability of the declared credible region")
    declare_without_wind: int = _p(0, 0, 1, "1 = declare also from a posterior begun without wind information "
                                   "(its confidence is then not calibrated: open-field, evaluation seeds 1000-1049, "
                                   "85 % of declarations within 3 m at a stated 0.95, the 90 % region held 62 %); "
                                   "0 = search without declaring")
    declare_confidence: float = _p(0.9, 0.5, 0.9999, "declare when the posterior probability that the source "
                                   "lies within success_radius_m of the credible disc's centre reaches this")
    declare_radius_m: float = _p(3.0, 0.1, 100.0, "... and the credible region's radius is at most this [m]")
    declare_hold_s: float = _p(5.0, 0.0, 600.0, "... both held this long, the centre within declare_radius_m of "
                               "where it was when they first held [s]")
    success_radius_m: float = _p(3.0, 0.1, 100.0, "confidence = posterior probability that the source lies "
                                 "within this distance of the declared point [m]")
    plume_model: str = _c("open", ("open", "urban"), "likelihood of a reading: 'open' the straight-line Gaussian "
                          "plume in the filtered wind; 'urban' backward paths through the urban diagnostic wind of "
                          "the buildings the mission knows, solved for the estimated inflow (ste_urban), with "
                          "moves routed around the buildings (without buildings: the open plume)")
    urban_cell_m: float = _p(4.0, 1.0, 20.0, "urban model: cell of the wind field's grid [m]")
    urban_path_step_m: float = _p(3.0, 0.5, 20.0, "urban model: step of a backward path [m]")
    urban_path_length_m: float = _p(240.0, 10.0, 2000.0, "urban model: length of a backward path [m]")
    urban_stall: float = _p(0.15, 0.0, 1.0, "urban model: mean wind slower than this share of the inflow (or "
                            "reversed) gives no direction: the path goes straight upwind through mixing air")
    urban_probe_above_m: float = _p(10.0, 0.0, 100.0, "urban model: the inflow is measured this far above the "
                                    "tallest known roof, over the start, before the search [m]")
    urban_probe_s: float = _p(8.0, 0.5, 120.0, "urban model: the inflow is the estimated wind averaged this long [s]")
    urban_decline_dead_air: int = _p(0, 0, 1, "urban model: 1 = no declaration at a point in stalled or reversed air "
                                     "at the flight altitude (a lee, a courtyard, a windward face)")
    urban_mix_rate: float = _p(0.15, 0.0, 5.0, "urban model: crosswind sigma added per metre of path through mixing "
                               "air [m/m]")


#: Fields where NaN means "not set" (documented per field).
NAN_ALLOWED = frozenset({"initial_heading_deg"})

PARAM_CLASSES: dict[str, type[CommonParams]] = {
    "anemotaxis": AnemotaxisParams,
    "surge-cast": SurgeCastParams,
    "zigzag": ZigzagParams,
    "infotaxis": InfotaxisParams,
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


def _check_field(where: str, f: Any, value: Any) -> float | int | str:
    """``value`` checked against the field's range or choices (``where``: the sub-table name or "")."""
    if "choices" in f.metadata:
        if value not in f.metadata["choices"]:
            name = f"strategy.{where}.{f.name}" if where else f"strategy.{f.name}"
            raise ParamError(f"{name} = {value!r}: allowed values are {', '.join(f.metadata['choices'])}")
        return str(value)
    lo, hi = f.metadata["range"]
    return _check(where, f.name, value, lo, hi, isinstance(f.default, int) and not isinstance(f.default, bool))


def validate(params: CommonParams, strategy: str = "") -> CommonParams:
    """Check every field of ``params`` against its range (ParamError naming the field)."""
    for f in fields(params):
        if "choices" in f.metadata:
            _check_field(strategy, f, getattr(params, f.name))
            continue
        lo, hi = f.metadata["range"]
        v = getattr(params, f.name)
        _check(strategy, f.name, v, lo, hi, isinstance(f.default, int) and not isinstance(f.default, bool))
    if params.descend_altitude_m > params.altitude_m:
        raise ParamError(
            f"strategy.descend_altitude_m = {params.descend_altitude_m}: must not exceed "
            f"strategy.altitude_m = {params.altitude_m}"
        )
    lo_hi = (("source_height_min_m", "source_height_max_m"), ("release_min_g_s", "release_max_g_s"))
    for lo_name, hi_name in lo_hi:
        if hasattr(params, lo_name) and getattr(params, lo_name) > getattr(params, hi_name):
            raise ParamError(f"strategy.{lo_name} = {getattr(params, lo_name)}: must not exceed "
                             f"strategy.{hi_name} = {getattr(params, hi_name)}")
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
        values[key] = _check_field(strategy if key in sub else "", f, v)
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
