"""The wind tables of a scenario: ``[wind]`` (mean wind, profile, schedule, model), ``[turbulence]``,
``[urban]`` (buildings and the grid of the urban wind). Every error names the field.

Conventions: wind = air-mass velocity in NED, m/s, or a speed and a from-direction in degrees.
"""

from __future__ import annotations

import math
from typing import Any

from sitl.parsing import ScenarioError, boolean, number, table, vec3
from sitl.world.wind import WIND_MODELS, KaimalTurbulence, SteadyWind, WindChange, velocity_from_speed_direction
from urbanflow.config import UrbanScene
from vehicle.frames import from_direction_deg

TURBULENCE_LEVELS = {"none": 0.0, "low": 0.5, "moderate": 1.0, "high": 2.0}


def _wind_vector(name: str, tbl: dict[str, Any]) -> tuple[float, float, float]:
    has_vec = "velocity_ned" in tbl
    has_dir = "speed_m_s" in tbl or "from_deg" in tbl
    if has_vec == has_dir:
        raise ScenarioError(
            f"{name}: give either velocity_ned = [n, e, d] (air-mass velocity, m/s) "
            "or speed_m_s and from_deg (from-direction, degrees)"
        )
    if has_vec:
        return vec3(f"{name}.velocity_ned", tbl["velocity_ned"], 100.0)
    speed = number(f"{name}.speed_m_s", tbl.get("speed_m_s"), 0.0, 100.0)
    from_deg = number(f"{name}.from_deg", tbl.get("from_deg"), -360.0, 360.0)
    vert = number(f"{name}.vertical_m_s", tbl.get("vertical_m_s", 0.0), -50.0, 50.0)
    return velocity_from_speed_direction(speed, from_deg, vert)


def parse_wind(tbl: dict[str, Any]) -> SteadyWind:
    table(
        "wind",
        tbl,
        {
            "velocity_ned", "speed_m_s", "from_deg", "vertical_m_s", "profile",
            "reference_height_m", "roughness_length_m", "changes", "direction_steps", "model", "options",
        },
    )  # fmt: skip
    profile = tbl.get("profile", "uniform")
    if profile not in ("uniform", "log"):
        raise ScenarioError(f"wind.profile = {profile!r}: allowed values are 'uniform', 'log'")
    kw: dict[str, Any] = {
        "profile": profile,
        "reference_height_m": number("wind.reference_height_m", tbl.get("reference_height_m", 10.0), 0.1, 1000.0),
        "roughness_length_m": number("wind.roughness_length_m", tbl.get("roughness_length_m", 0.1), 1e-4, 5.0),
    }
    if "direction_steps" in tbl:
        ds = table("wind.direction_steps", tbl["direction_steps"], {"speed_m_s", "from_deg", "interval_s"})
        froms = ds.get("from_deg")
        if not isinstance(froms, list) or not froms:
            raise ScenarioError("wind.direction_steps.from_deg: expected a non-empty list of degrees")
        return SteadyWind.direction_steps(
            number("wind.direction_steps.speed_m_s", ds.get("speed_m_s"), 0.0, 100.0),
            [number(f"wind.direction_steps.from_deg[{i}]", f, -360, 360) for i, f in enumerate(froms)],
            number("wind.direction_steps.interval_s", ds.get("interval_s"), 0.1, 1e5),
            **kw,
        )
    vec_keys = {"velocity_ned", "speed_m_s", "from_deg", "vertical_m_s"}
    base = _wind_vector("wind", {k: v for k, v in tbl.items() if k in vec_keys})
    changes = []
    raw = tbl.get("changes", [])
    if not isinstance(raw, list):
        raise ScenarioError("wind.changes: expected a list of {t_s = ..., velocity_ned = [...]} tables")
    for i, ch in enumerate(raw):
        name = f"wind.changes[{i}]"
        ch = table(name, ch, {"t_s", "velocity_ned", "speed_m_s", "from_deg", "vertical_m_s"})
        t = number(f"{name}.t_s", ch.get("t_s"), 0.0, 1e6)
        changes.append(WindChange(t, _wind_vector(name, {k: v for k, v in ch.items() if k != "t_s"})))
    try:
        return SteadyWind(velocity_ned=base, changes=tuple(changes), **kw)
    except ValueError as e:
        raise ScenarioError(f"wind: {e}") from None


def parse_wind_model(tbl: dict[str, Any]) -> tuple[str, tuple[tuple[str, Any], ...]]:
    """``[wind] model`` (default "steady") and its ``[wind.options]`` table."""
    model = tbl.get("model", "steady")
    if model not in WIND_MODELS:
        raise ScenarioError(f"wind.model = {model!r}: allowed values are {', '.join(map(repr, sorted(WIND_MODELS)))}")
    options = tbl.get("options", {})
    if not isinstance(options, dict):
        raise ScenarioError(f"[wind.options]: expected a table of the wind model's options, got {options!r}")
    return str(model), tuple(sorted(options.items()))


def parse_urban(tbl: Any, wind: SteadyWind, wind_model: str) -> UrbanScene:
    """``[urban]``: buildings, the wind grid, options; the upstream profile is the scenario's ``[wind]``
    (one source of truth: a log profile, no schedule, since the solved field is steady)."""
    from sitl.world.urban.parse import parse_urban_scene
    from urbanflow.config import ConfigError

    t = table("urban", tbl, {"buildings", "grid", "options", "name"})
    if wind_model not in ("steady", "urban"):
        raise ScenarioError(f"wind.model = {wind_model!r}: a scenario with [urban] uses the urban wind model")
    if wind.profile != "log" or wind.changes:
        raise ScenarioError("[urban] needs [wind] with profile = 'log' and no changes / direction_steps "
                            "(the urban field is solved once, for one upstream log profile)")  # fmt: skip
    n, e, _ = wind.velocity_ned
    profile = {"speed_m_s": math.hypot(n, e), "from_deg": float(from_direction_deg(n, e)),
               "reference_height_m": wind.reference_height_m,
               "roughness_length_m": wind.roughness_length_m}  # fmt: skip
    try:
        return parse_urban_scene({k: v for k, v in t.items() if k != "name"} | {"wind": profile},
                                 name=str(t.get("name", "")))  # fmt: skip
    except ConfigError as err:
        raise ScenarioError(f"urban.{err}") from None


def parse_turbulence(tbl: dict[str, Any], wind: SteadyWind, duration: float) -> KaimalTurbulence | None:
    table(
        "turbulence",
        tbl,
        {"model", "level", "sigma_u_m_s", "intensity", "intensity_class", "height_m", "taylor", "sample_rate_hz"},
    )
    model = tbl.get("model", "kaimal")
    if model not in ("kaimal", "none"):
        raise ScenarioError(f"turbulence.model = {model!r}: allowed values are 'kaimal', 'none'")
    if model == "none":
        return None
    given = [k for k in ("level", "sigma_u_m_s", "intensity", "intensity_class") if k in tbl]
    if len(given) != 1:
        raise ScenarioError(
            "turbulence: give exactly one of level ('low', 'moderate', 'high'), sigma_u_m_s, "
            f"intensity, intensity_class ('A', 'B', 'C'); got {given or 'none'}"
        )
    u_mean = math.hypot(wind.velocity_ned[0], wind.velocity_ned[1])
    kw: dict[str, Any] = {
        "height_m": number("turbulence.height_m", tbl.get("height_m", 10.0), 0.5, 500.0),
        "taylor": boolean("turbulence.taylor", tbl.get("taylor", True)),
        "sample_rate_hz": number("turbulence.sample_rate_hz", tbl.get("sample_rate_hz", 50.0), 1.0, 1000.0),
        # Periodic series: make it at least as long as the run (and 10 minutes).
        "duration_s": max(600.0, duration + 10.0),
    }
    try:
        if "level" in tbl:
            lvl = tbl["level"]
            if lvl not in TURBULENCE_LEVELS:
                raise ScenarioError(
                    f"turbulence.level = {lvl!r}: allowed values are {', '.join(TURBULENCE_LEVELS)}"
                )
            if TURBULENCE_LEVELS[lvl] == 0.0:
                return None
            return KaimalTurbulence(sigma_u=TURBULENCE_LEVELS[lvl], **kw)
        if "sigma_u_m_s" in tbl:
            return KaimalTurbulence(sigma_u=number("turbulence.sigma_u_m_s", tbl["sigma_u_m_s"], 0.0, 20.0), **kw)
        if "intensity" in tbl:
            ti = number("turbulence.intensity", tbl["intensity"], 0.0, 1.0)
            return KaimalTurbulence.from_intensity(ti, max(u_mean, 1.0), **kw)
        cls = tbl["intensity_class"]
        if cls not in ("A", "B", "C"):
            raise ScenarioError(f"turbulence.intensity_class = {cls!r}: allowed values are 'A', 'B', 'C'")
        return KaimalTurbulence.from_intensity_class(cls, max(u_mean, 1.0), **kw)
    except ScenarioError:
        raise
    except ValueError as e:
        raise ScenarioError(f"turbulence: {e}") from None
