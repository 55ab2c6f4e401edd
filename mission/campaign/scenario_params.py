"""Scenario parameters of a campaign grid: a value set into a scenario's TOML table before it is parsed.

A parameter is either a dotted path into the scenario table (``wind.speed_m_s``,
``plume.sensor.detection_limit_mg_m3``, ``plume.sources[0].rate_g_s``) or one of the names of
:data:`ALIASES` (``wind_speed_m_s``, ``turbulence_intensity``, ``stability``, ...), plus
``start_distance_m``, which moves the (single) source that far upwind of the start along the
wind's from-direction, at its own height. Every value is then validated by the scenario parser
(:func:`sitl.scenario.parse_scenario`), whose errors name the field and the allowed range.

Keys of a table that exclude each other are handled: setting one of the turbulence keys
(``level``, ``sigma_u_m_s``, ``intensity``, ``intensity_class``) removes the others (and turns a
``model = "none"`` into Kaimal turbulence); setting the wind speed or direction of a wind given as
``velocity_ned`` converts it to speed + from-direction first. Units SI, angles in degrees
(from-direction, 0 = from north), NED.
"""

from __future__ import annotations

import copy
import math
import re
from typing import Any

from sitl.parsing import ScenarioError
from sitl.scenario import TOP_KEYS

#: Short names for the parameters swept most often -> the path they set.
ALIASES: dict[str, str] = {
    "wind_speed_m_s": "wind.speed_m_s",
    "wind_from_deg": "wind.from_deg",
    "turbulence_level": "turbulence.level",
    "turbulence_intensity": "turbulence.intensity",
    "sigma_u_m_s": "turbulence.sigma_u_m_s",
    "stability": "plume.stability",
    "sensor_threshold_mg_m3": "plume.sensor.detection_limit_mg_m3",
    "source_rate_g_s": "plume.sources[0].rate_g_s",
}
#: Parameters computed from the others rather than set at one path.
DERIVED = ("start_distance_m",)
TURBULENCE_CHOICES = ("level", "sigma_u_m_s", "intensity", "intensity_class")
WIND_POLAR = ("speed_m_s", "from_deg", "vertical_m_s")
_SEGMENT = re.compile(r"^([A-Za-z_][A-Za-z0-9_-]*)(?:\[(\d+)\])?$")


def check_name(name: str) -> None:
    """Raise ScenarioError unless ``name`` is an alias, a derived parameter or a path into the table."""
    if name in ALIASES or name in DERIVED:
        return
    segments = name.split(".")
    if not all(_SEGMENT.match(s) for s in segments):
        raise ScenarioError(f"scenario parameter {name!r}: not a dotted path (e.g. wind.speed_m_s)")
    head = _SEGMENT.match(segments[0])
    assert head is not None
    if len(segments) == 1 or head.group(1) not in TOP_KEYS:
        raise ScenarioError(
            f"unknown scenario parameter {name!r}: give a dotted path into the scenario table "
            f"(top-level keys: {', '.join(sorted(TOP_KEYS))}) or one of {', '.join([*ALIASES, *DERIVED])}"
        )


def apply(base: dict[str, Any], params: dict[str, Any]) -> dict[str, Any]:
    """A deep copy of the scenario table ``base`` with every parameter of ``params`` set."""
    tbl = copy.deepcopy(base)
    for name, value in params.items():
        if name not in DERIVED:
            _set_path(tbl, ALIASES.get(name, name), value)
    if "start_distance_m" in params:
        _place_source(tbl, params["start_distance_m"])
    return tbl


def _set_path(tbl: dict[str, Any], path: str, value: Any) -> None:
    *parents, last = path.split(".")
    node: Any = tbl
    walked: list[str] = []
    for seg in parents:
        node = _child(node, seg, walked)
        walked.append(seg)
    m = _SEGMENT.match(last)
    assert m is not None
    key, index = m.group(1), m.group(2)
    if not isinstance(node, dict):
        raise ScenarioError(f"{'.'.join(walked)}: not a table, cannot set {last}")
    if walked == ["turbulence"] and key in TURBULENCE_CHOICES:
        for other in TURBULENCE_CHOICES:
            node.pop(other, None)
        if node.get("model") == "none":
            node["model"] = "kaimal"
    if walked == ["wind"] and key in WIND_POLAR and "velocity_ned" in node:
        _wind_to_polar(node)
    if walked == ["wind"] and key == "velocity_ned":
        for other in WIND_POLAR:
            node.pop(other, None)
    if index is None:
        node[key] = copy.deepcopy(value)
        return
    seq = node.get(key)
    if not isinstance(seq, list) or int(index) >= len(seq):
        raise ScenarioError(f"{'.'.join([*walked, key])}: has no element [{index}]")
    seq[int(index)] = copy.deepcopy(value)


def _child(node: Any, seg: str, walked: list[str]) -> Any:
    """The sub-table ``seg`` (``key`` or ``key[i]``) of ``node``, created if a plain key is missing."""
    m = _SEGMENT.match(seg)
    assert m is not None
    key, index = m.group(1), m.group(2)
    where = ".".join([*walked, key])
    if not isinstance(node, dict):
        raise ScenarioError(f"{'.'.join(walked)}: not a table, has no {seg}")
    if index is None:
        return node.setdefault(key, {})
    seq = node.get(key)
    if not isinstance(seq, list) or int(index) >= len(seq):
        raise ScenarioError(f"{where}: has no element [{index}]")
    return seq[int(index)]


def _wind_to_polar(wind: dict[str, Any]) -> None:
    """``velocity_ned = [n, e, d]`` -> ``speed_m_s``, ``from_deg``, ``vertical_m_s`` (air-mass velocity NED)."""
    v = wind.pop("velocity_ned")
    if not isinstance(v, list) or len(v) != 3 or not all(isinstance(c, int | float) for c in v):
        raise ScenarioError(f"wind.velocity_ned = {v!r}: expected 3 numbers [north, east, down]")
    n, e, d = (float(c) for c in v)
    wind["speed_m_s"] = math.hypot(n, e)
    wind["from_deg"] = math.degrees(math.atan2(-e, -n)) % 360.0  # air moving south comes from the north
    wind["vertical_m_s"] = d


def _place_source(tbl: dict[str, Any], distance: Any) -> None:
    """Put the scenario's single source ``distance`` m upwind of the start (its height kept)."""
    if isinstance(distance, bool) or not isinstance(distance, int | float) or not 0.0 < distance <= 1e5:
        raise ScenarioError(f"start_distance_m = {distance!r}: expected a number in (0, 100000] m")
    plume = tbl.get("plume")
    sources = plume.get("sources") if isinstance(plume, dict) else None
    if not isinstance(sources, list) or len(sources) != 1 or not isinstance(sources[0], dict):
        raise ScenarioError("start_distance_m: needs a scenario with a [plume] table and exactly one source")
    wind = tbl.get("wind", {})
    if not isinstance(wind, dict):
        raise ScenarioError("start_distance_m: [wind] must be a table")
    if "velocity_ned" in wind:
        _wind_to_polar(wind)
    if "from_deg" in wind:
        from_deg = wind["from_deg"]
    elif isinstance(wind.get("direction_steps"), dict) and wind["direction_steps"].get("from_deg"):
        from_deg = wind["direction_steps"]["from_deg"][0]
    else:
        raise ScenarioError("start_distance_m: needs a wind direction (wind.from_deg or wind.velocity_ned)")
    if isinstance(from_deg, bool) or not isinstance(from_deg, int | float):
        raise ScenarioError(f"wind.from_deg = {from_deg!r}: expected a number of degrees")
    start = tbl.get("start", {}).get("position_ned", [0.0, 0.0, 0.0]) if isinstance(tbl.get("start"), dict) else None
    if not isinstance(start, list) or len(start) != 3:
        raise ScenarioError("start.position_ned: expected 3 numbers [north, east, down]")
    pos = sources[0].get("position_ned", [0.0, 0.0, -2.0])
    height = pos[2] if isinstance(pos, list) and len(pos) == 3 else -2.0
    a = math.radians(float(from_deg))  # the wind comes from there: the source is that way
    sources[0]["position_ned"] = [round(float(start[0]) + distance * math.cos(a), 9),
                                  round(float(start[1]) + distance * math.sin(a), 9), height]  # fmt: skip
