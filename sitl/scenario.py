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
from sitl.scenario_wind import parse_turbulence, parse_urban, parse_wind, parse_wind_model
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
from sitl.world.spec import Start, WorldSpec
from sitl.world.wind import KaimalTurbulence, SteadyWind
from urbanflow.config import UrbanScene
from vehicle.geomag import earth_field_ned_gauss


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
    urban: UrbanScene | None = None  # the parsed [urban] table: buildings and the wind grid
    source_path: str = ""

    def with_seed(self, seed: int) -> Scenario:
        return replace(self, seed=int(seed))

    def world_spec(self) -> WorldSpec:
        """What the world alone takes (:class:`~sitl.world.spec.WorldSpec`): no gains, flight
        settings, route or duration."""
        return WorldSpec(name=self.name, seed=self.seed, vehicle=self.vehicle, physics_rate_hz=self.physics_rate_hz,
                         mode_rate_hz=self.mode_rate_hz, wind=self.wind, turbulence=self.turbulence,
                         wind_model=self.wind_model, wind_options=self.wind_options, start=self.start,
                         sensors=self.sensors, plume=self.plume, urban=self.urban)  # fmt: skip

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


def _parse_mag(mag: Any, home: Any) -> MagConfig:
    """``[sensors.mag]``; without ``field_ned_gauss`` the World Magnetic Model's field at the home (as the
    autopilots assume it: :mod:`vehicle.geomag`)."""
    cfg = _parse_dataclass("sensors.mag", MagConfig, mag)
    if isinstance(mag, dict) and "field_ned_gauss" in mag:
        return cfg
    h = _parse_dataclass("sensors.home", HomeConfig, home)
    if (h.lat_deg, h.lon_deg) == (HomeConfig.lat_deg, HomeConfig.lon_deg):
        return cfg  # the default home's field is the dataclass default (no model evaluation)
    if not (-90 <= h.lat_deg <= 90 and -180 <= h.lon_deg <= 180):
        return cfg  # validate() names the bad home
    return replace(cfg, field_ned_gauss=earth_field_ned_gauss(h.lat_deg, h.lon_deg, h.alt_m))


def _parse_sensors(tbl: Any, physics_rate_hz: float) -> SensorSuiteConfig:
    sens = table("sensors", tbl, {"imu", "esc", "gnss", "baro", "mag", "temperature", "home"})
    sensors = SensorSuiteConfig(
        imu=_parse_dataclass("sensors.imu", ImuConfig, sens.get("imu")),
        esc=_parse_dataclass("sensors.esc", EscConfig, sens.get("esc")),
        gnss=_parse_dataclass("sensors.gnss", GnssConfig, sens.get("gnss")),
        baro=_parse_dataclass("sensors.baro", BaroConfig, sens.get("baro")),
        mag=_parse_mag(sens.get("mag"), sens.get("home")),
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
    "start", "route", "sensors", "controller", "flight", "plume", "urban",
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
    wind = parse_wind(data.get("wind", {"velocity_ned": [0.0, 0.0, 0.0]}))
    turb = parse_turbulence(data.get("turbulence", {"model": "none"}), wind, duration)
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
    wind_model, wind_options = parse_wind_model(data.get("wind", {}))
    urban = None
    if "urban" in data:
        urban = parse_urban(data["urban"], wind, wind_model)
        wind_model, wind_options = "urban", (*wind_options, ("scene", urban))
        _check_clear_of_buildings(urban, start, plume)
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
        urban=urban,
        source_path=source,
    )


def _check_clear_of_buildings(urban: UrbanScene, start: Start, plume: PlumeSetup | None) -> None:
    """ScenarioError naming the field when the start or a plume source lies inside a building."""
    from urbanflow.geometry import BuildingArrays, building_at

    arrays = BuildingArrays.from_buildings(urban.buildings)
    points = [("start.position_ned", start.position_ned)]
    if plume is not None:
        points += [(f"plume.sources[{i}].position_ned", s.position_ned) for i, s in enumerate(plume.plume.sources)]
    for name, p in points:
        b = building_at(float(p[0]), float(p[1]), -float(p[2]), *arrays.args())
        if b >= 0:
            label = getattr(urban.buildings[b], "name", "") or f"urban.buildings[{b}]"
            raise ScenarioError(f"{name} = {list(p)}: inside building {label!r}")


def builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped with the package."""
    folder = resources.files("sitl") / "scenarios"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def scenario_table(name_or_path: str | Path) -> tuple[dict[str, Any], str]:
    """The parsed TOML table of a built-in scenario (by name) or a scenario file (by path), not yet
    validated, and its source (``builtin:NAME`` or the path): for callers that vary it before
    :func:`parse_scenario` (campaign grids). A relative vehicle ``.toml`` path is made absolute."""
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
    return data, source


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name (``paper-s1``) or a TOML file by path."""
    data, source = scenario_table(name_or_path)
    return parse_scenario(data, source)
