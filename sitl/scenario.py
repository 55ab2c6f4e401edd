"""Scenario files: TOML a user can copy and edit. Built-ins live in ``sitl/scenarios/``.

Every error names the offending field and the allowed values. The format is documented in
the README ("Scenario file format"); ``sitl/scenarios/paper-s2.toml`` is a full example.
Conventions: SI units, NED world frame, wind as air-mass velocity in NED, or as a speed and
a *from*-direction in degrees (0 = from north, 90 = from east).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from sitl.autopilot.controller import ControllerGains
from sitl.autopilot.flight_modes import FlightConfig, ItemKind, MissionItem
from sitl.parsing import ScenarioError, boolean, number, table, vec3
from sitl.world.plume.setup import PlumeSetup, parse_plume_table
from sitl.world.sensors import (
    BaroConfig,
    EscConfig,
    GnssConfig,
    HomeConfig,
    ImuConfig,
    MagConfig,
    SensorSuiteConfig,
    TemperatureConfig,
)
from sitl.world.wind import WIND_MODELS, KaimalTurbulence, SteadyWind, WindChange, velocity_from_speed_direction

TURBULENCE_LEVELS = {"none": 0.0, "low": 0.5, "moderate": 1.0, "high": 2.0}


@dataclass(frozen=True)
class Waypoint:
    position_ned: tuple[float, float, float]
    hold_s: float = 0.0
    acceptance_radius_m: float = 1.0
    speed_m_s: float = math.nan


@dataclass(frozen=True)
class Route:
    """The commanded path flown by ``windseek sim``: take-off (unless airborne), waypoints, land."""

    takeoff_altitude_m: float = 10.0
    cruise_speed_m_s: float = 3.0
    waypoints: tuple[Waypoint, ...] = ()
    land: bool = False


@dataclass(frozen=True)
class Start:
    position_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_deg: float = 0.0
    airborne: bool = False


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str = ""
    duration_s: float = 60.0
    seed: int = 0
    vehicle: str = "nasa-quad"
    physics_rate_hz: float = 500.0
    mode_rate_hz: float = 50.0
    wind: SteadyWind = field(default_factory=lambda: SteadyWind(velocity_ned=(0.0, 0.0, 0.0)))
    turbulence: KaimalTurbulence | None = None
    wind_model: str = "steady"  # a name in sitl.world.wind.model.WIND_MODELS
    wind_options: tuple[tuple[str, Any], ...] = ()  # the [wind.options] table, for the wind model
    start: Start = field(default_factory=Start)
    route: Route = field(default_factory=Route)
    sensors: SensorSuiteConfig = field(default_factory=SensorSuiteConfig)
    gains: ControllerGains = field(default_factory=ControllerGains)
    flight: FlightConfig = field(default_factory=FlightConfig)
    plume: PlumeSetup | None = None  # the parsed [plume] table
    source_path: str = ""

    def with_seed(self, seed: int) -> Scenario:
        return replace(self, seed=int(seed))

    def with_duration(self, duration_s: float) -> Scenario:
        number("duration_s", duration_s, 0.01, 86400.0)
        return replace(self, duration_s=float(duration_s))

    def mission_items(self) -> list[MissionItem]:
        """The route as autopilot mission items (NED)."""
        items: list[MissionItem] = []
        if not self.start.airborne:
            items.append(
                MissionItem(
                    ItemKind.TAKEOFF,
                    np.array([math.nan, math.nan, -self.route.takeoff_altitude_m]),
                    acceptance_radius_m=0.5,
                )
            )
        for wp in self.route.waypoints:
            if math.isfinite(wp.speed_m_s):
                items.append(MissionItem(ItemKind.CHANGE_SPEED, speed_m_s=wp.speed_m_s))
            items.append(
                MissionItem(
                    ItemKind.WAYPOINT,
                    np.array(wp.position_ned, dtype=float),
                    acceptance_radius_m=wp.acceptance_radius_m,
                    hold_s=wp.hold_s,
                )
            )
        if self.route.land:
            items.append(MissionItem(ItemKind.LAND))
        return items


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


def _parse_wind(tbl: dict[str, Any]) -> SteadyWind:
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


def _parse_wind_model(tbl: dict[str, Any]) -> tuple[str, tuple[tuple[str, Any], ...]]:
    """``[wind] model`` (default "steady") and its ``[wind.options]`` table."""
    model = tbl.get("model", "steady")
    if model not in WIND_MODELS:
        raise ScenarioError(f"wind.model = {model!r}: allowed values are {', '.join(map(repr, sorted(WIND_MODELS)))}")
    options = tbl.get("options", {})
    if not isinstance(options, dict):
        raise ScenarioError(f"[wind.options]: expected a table of the wind model's options, got {options!r}")
    return str(model), tuple(sorted(options.items()))


def _parse_turbulence(tbl: dict[str, Any], wind: SteadyWind, duration: float) -> KaimalTurbulence | None:
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


def _parse_dataclass(name: str, cls: type, tbl: Any, angle_fields: tuple[str, ...] = ()) -> Any:
    """Override a config dataclass from a table; unknown keys and bad values are errors."""
    if tbl is None:
        return cls()
    allowed = {f.name for f in fields(cls)}
    alias = {f"{a}_deg": a for a in angle_fields}
    tbl = table(name, tbl, allowed | set(alias))
    kw: dict[str, Any] = {}
    for k, v in tbl.items():
        key = alias.get(k, k)
        default = getattr(cls(), key)
        if isinstance(default, bool):
            kw[key] = boolean(f"{name}.{k}", v)
        elif isinstance(default, int) and not isinstance(default, bool):
            kw[key] = int(number(f"{name}.{k}", v, 0, 1e9))
        elif isinstance(default, tuple):
            kw[key] = vec3(f"{name}.{k}", v)
        else:
            val = number(f"{name}.{k}", v, -1e9, 1e9)
            kw[key] = math.radians(val) if k in alias else val
    return cls(**kw)


def _parse_route(tbl: dict[str, Any] | None) -> Route:
    if tbl is None:
        return Route()
    table("route", tbl, {"takeoff_altitude_m", "cruise_speed_m_s", "waypoints", "land"})
    wps = []
    raw = tbl.get("waypoints", [])
    if not isinstance(raw, list):
        raise ScenarioError("route.waypoints: expected a list of {position_ned = [...], hold_s = ...} tables")
    for i, w in enumerate(raw):
        name = f"route.waypoints[{i}]"
        w = table(name, w, {"position_ned", "hold_s", "acceptance_radius_m", "speed_m_s"})
        if "position_ned" not in w:
            raise ScenarioError(f"{name}.position_ned: required ([north, east, down] m)")
        pos = vec3(f"{name}.position_ned", w["position_ned"])
        if pos[2] > 0:
            raise ScenarioError(f"{name}.position_ned[2] = {pos[2]}: must be <= 0 (NED: down is positive)")
        wps.append(
            Waypoint(
                pos,
                number(f"{name}.hold_s", w.get("hold_s", 0.0), 0.0, 1e5),
                number(f"{name}.acceptance_radius_m", w.get("acceptance_radius_m", 1.0), 0.1, 100.0),
                number(f"{name}.speed_m_s", w["speed_m_s"], 0.1, 20.0) if "speed_m_s" in w else math.nan,
            )
        )
    return Route(
        takeoff_altitude_m=number("route.takeoff_altitude_m", tbl.get("takeoff_altitude_m", 10.0), 0.5, 500.0),
        cruise_speed_m_s=number("route.cruise_speed_m_s", tbl.get("cruise_speed_m_s", 3.0), 0.1, 20.0),
        waypoints=tuple(wps),
        land=boolean("route.land", tbl.get("land", False)),
    )


def _parse_start(tbl: Any) -> Start:
    st = table("start", tbl, {"position_ned", "yaw_deg", "airborne"})
    start = Start(
        vec3("start.position_ned", st.get("position_ned", [0.0, 0.0, 0.0])),
        number("start.yaw_deg", st.get("yaw_deg", 0.0), -360.0, 360.0),
        boolean("start.airborne", st.get("airborne", False)),
    )
    if start.airborne and start.position_ned[2] >= -0.5:
        raise ScenarioError("start.position_ned[2]: an airborne start needs an altitude (z <= -0.5 m, NED)")
    if not start.airborne and start.position_ned[2] != 0.0:
        raise ScenarioError("start.position_ned[2]: a ground start must have z = 0 (set airborne = true)")
    return start


def _parse_sensors(tbl: Any, physics_rate_hz: float) -> SensorSuiteConfig:
    sens = table("sensors", tbl, {"imu", "esc", "gnss", "baro", "mag", "temperature", "home"})
    sensors = SensorSuiteConfig(
        imu=_parse_dataclass("sensors.imu", ImuConfig, sens.get("imu")),
        esc=_parse_dataclass("sensors.esc", EscConfig, sens.get("esc")),
        gnss=_parse_dataclass("sensors.gnss", GnssConfig, sens.get("gnss")),
        baro=_parse_dataclass("sensors.baro", BaroConfig, sens.get("baro")),
        mag=_parse_dataclass("sensors.mag", MagConfig, sens.get("mag")),
        temperature=_parse_dataclass("sensors.temperature", TemperatureConfig, sens.get("temperature")),
        home=_parse_dataclass("sensors.home", HomeConfig, sens.get("home")),
    )
    try:
        sensors.validate(physics_rate_hz)
    except ValueError as e:
        raise ScenarioError(str(e)) from None
    return sensors


TOP_KEYS = {
    "name", "description", "duration_s", "seed", "vehicle", "physics", "wind", "turbulence",
    "start", "route", "sensors", "controller", "flight", "plume",
}  # fmt: skip


def parse_scenario(data: dict[str, Any], source: str = "<dict>") -> Scenario:
    """Build a validated :class:`Scenario` from a parsed TOML document."""
    table("scenario", data, TOP_KEYS)
    if "name" not in data:
        raise ScenarioError("name: required (a non-empty string naming the scenario)")
    name = data["name"]
    if not isinstance(name, str) or not name.strip():
        raise ScenarioError(f"name = {name!r}: expected a non-empty string")
    duration = number("duration_s", data.get("duration_s", 60.0), 0.01, 86400.0)
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ScenarioError(f"seed = {seed!r}: expected an integer >= 0")
    phys = table("physics", data.get("physics", {}), {"rate_hz", "mode_rate_hz"})
    rate = number("physics.rate_hz", phys.get("rate_hz", 500.0), 100.0, 10000.0)
    mode_rate = number("physics.mode_rate_hz", phys.get("mode_rate_hz", 50.0), 1.0, rate)
    if abs(rate / mode_rate - round(rate / mode_rate)) > 1e-9:
        raise ScenarioError(f"physics.mode_rate_hz = {mode_rate}: must divide physics.rate_hz = {rate}")
    wind = _parse_wind(data.get("wind", {"velocity_ned": [0.0, 0.0, 0.0]}))
    turb = _parse_turbulence(data.get("turbulence", {"model": "none"}), wind, duration)
    start = _parse_start(data.get("start", {}))
    sensors = _parse_sensors(data.get("sensors", {}), rate)
    gains = _parse_dataclass(
        "controller", ControllerGains, data.get("controller"),
        angle_fields=("tilt_max", "rate_max_rp", "rate_max_yaw"),
    )  # fmt: skip
    try:
        gains.validate()
    except ValueError as e:
        raise ScenarioError(str(e)) from None
    route = _parse_route(data.get("route"))
    flight = _parse_dataclass("flight", FlightConfig, data.get("flight"))
    flight = replace(flight, takeoff_altitude_m=route.takeoff_altitude_m, cruise_speed_m_s=route.cruise_speed_m_s)
    raw_plume = data.get("plume")
    plume = None if raw_plume is None else parse_plume_table(raw_plume, mode_rate)
    wind_model, wind_options = _parse_wind_model(data.get("wind", {}))
    vehicle = data.get("vehicle", "nasa-quad")
    if not isinstance(vehicle, str):
        raise ScenarioError("vehicle: expected a vehicle name ('nasa-quad') or a .toml path")
    return Scenario(
        name=name,
        description=str(data.get("description", "")),
        duration_s=duration,
        seed=seed,
        vehicle=vehicle,
        physics_rate_hz=rate,
        mode_rate_hz=mode_rate,
        wind=wind,
        turbulence=turb,
        wind_model=wind_model,
        wind_options=wind_options,
        start=start,
        route=route,
        sensors=sensors,
        gains=gains,
        flight=flight,
        plume=plume,
        source_path=source,
    )


def builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped with the package."""
    folder = resources.files("sitl") / "scenarios"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name (``paper-s1``) or a TOML file by path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ScenarioError(f"scenario file {p} does not exist")
        text = p.read_bytes()
        source = str(p)
    else:
        res = resources.files("sitl") / "scenarios" / f"{name_or_path}.toml"
        if not res.is_file():
            raise ScenarioError(
                f"unknown scenario {str(name_or_path)!r}: built-ins are {', '.join(builtin_scenarios())}, "
                "or give a path to a .toml file"
            )
        text = res.read_bytes()
        source = f"builtin:{name_or_path}"
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{source}: not a TOML text file (byte {e.start} is not UTF-8)") from None
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{source}: TOML syntax error: {e}") from None
    if "vehicle" in data and isinstance(data["vehicle"], str) and data["vehicle"].endswith(".toml"):
        vp = Path(data["vehicle"])
        if not vp.is_absolute() and p.suffix == ".toml":
            data["vehicle"] = str((p.parent / vp).resolve())
    return parse_scenario(data, source)
