"""The buildings uploaded to the autopilot as geofence exclusion polygons (MAVSDK geofence plugin).

A user flying among buildings with PX4 would load their footprints as exclusion zones of the
autopilot's geofence, so the autopilot itself refuses to fly into them; the mission runner does the
same with the buildings it clamps its setpoints around (:mod:`mission.obstacles`).

Frames: a scenario's buildings are in the scenario's NED frame, whose geodetic origin is the
scenario's ``[sensors.home]``; the runner flies in the autopilot's local NED frame (LOCAL_POSITION_NED),
whose origin is where the autopilot's estimator started: the same point for windseek's own SITL,
the vehicle's start for PX4 (SITL, HIL or real). The local origin is read from HOME_POSITION (its
geodetic position minus its local offset), the buildings are moved by the difference of the two
origins, and the geofence is placed on the local origin: all on a flat earth, the projection the
autopilots use over a few kilometres.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mission.obstacles import Obstacles
from mission.vehicle import CommandError

EARTH_RADIUS_M = 6_378_137.0


@dataclass(frozen=True)
class SiteBuildings:
    """A scenario's buildings (scenario NED frame) and that frame's geodetic origin (deg)."""

    obstacles: Obstacles
    origin_deg: tuple[float, float]

    @classmethod
    def from_scenario_file(cls, path: str | Path, margin_m: float = 3.0) -> SiteBuildings:
        """The ``[urban]`` buildings of a scenario (name or file) and its ``[sensors.home]`` origin."""
        from sitl.scenario import load_scenario

        sc = load_scenario(str(path))
        if sc.urban is None or not sc.urban.buildings:
            raise ValueError(f"{path}: the scenario has no [urban] buildings")
        home = sc.sensors.home
        return cls(Obstacles.from_buildings(sc.urban.buildings, margin_m), (home.lat_deg, home.lon_deg))

    def in_local_frame(self, local_origin_deg: tuple[float, float]) -> Obstacles:
        """The buildings in the local frame of an autopilot whose origin is ``local_origin_deg``."""
        north, east = latlon_to_ned(*self.origin_deg, *local_origin_deg)
        return self.obstacles.shifted(north, east)


def ned_to_latlon(north_m: float, east_m: float, origin_lat_deg: float, origin_lon_deg: float) -> tuple[float, float]:
    """Flat-earth local NED (m) to latitude, longitude (deg) around a geodetic origin."""
    lat = origin_lat_deg + math.degrees(north_m / EARTH_RADIUS_M)
    lon = origin_lon_deg + math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(origin_lat_deg))))
    return lat, lon


def latlon_to_ned(lat_deg: float, lon_deg: float, origin_lat_deg: float, origin_lon_deg: float) -> tuple[float, float]:
    """Inverse of :func:`ned_to_latlon`: (north, east) m of a point from a geodetic origin."""
    north = math.radians(lat_deg - origin_lat_deg) * EARTH_RADIUS_M
    east = math.radians(lon_deg - origin_lon_deg) * EARTH_RADIUS_M * math.cos(math.radians(origin_lat_deg))
    return north, east


def local_origin(home: dict[str, Any]) -> tuple[float, float]:
    """The local frame's geodetic origin (deg) from a HOME_POSITION's fields (degE7 and local m)."""
    lat0, lon0 = home["latitude"] * 1e-7, home["longitude"] * 1e-7
    # HOME_POSITION's x, y are home's position in the local frame: step back by them.
    return ned_to_latlon(-float(home["x"]), -float(home["y"]), lat0, lon0)


async def upload_exclusions(drone: Any, obstacles: Obstacles, origin: tuple[float, float],
                            timeout_s: float = 10.0) -> int:  # fmt: skip
    """Upload every building footprint (local frame, as is: the supervisor keeps the margin) as an
    EXCLUSION polygon placed on the local ``origin``; returns how many. CommandError when the
    autopilot refuses or does not answer."""
    from mavsdk.asyncio.plugins.geofence import GeofenceAsync
    from mavsdk.plugins.geofence import FenceType, GeofenceData, Point, Polygon

    polygons = []
    for b in obstacles.buildings:
        pts = [Point(*ned_to_latlon(float(n), float(e), *origin)) for n, e in b.footprint]
        polygons.append(Polygon(pts, FenceType.EXCLUSION))
    try:
        await asyncio.wait_for(GeofenceAsync(drone).upload_geofence(GeofenceData(polygons, [])), timeout_s)
    except TimeoutError:
        raise CommandError(f"geofence upload: no answer within {timeout_s:g} s") from None
    except Exception as e:  # noqa: BLE001 - GeofenceError: the autopilot's reason
        raise CommandError(f"geofence upload: {e}") from None
    return len(polygons)


async def place_buildings(site: SiteBuildings, home: Callable[[], dict[str, Any] | None], drone: Any,
                          say: Callable[[str], None], wait_s: float) -> Obstacles:  # fmt: skip
    """Wait (at most ``wait_s`` wall seconds) for the autopilot's HOME_POSITION, move the buildings
    into its local frame and upload them as exclusion zones; the buildings in the local frame.
    CommandError when there is no HOME_POSITION or the upload fails: a mission told to avoid
    buildings does not fly without knowing where they are."""
    end = asyncio.get_running_loop().time() + wait_s
    while (h := home()) is None:
        if asyncio.get_running_loop().time() > end:
            raise CommandError(f"no HOME_POSITION within {wait_s:g} s: cannot place the buildings")
        await asyncio.sleep(0.05)
    origin = local_origin(h)
    local = site.in_local_frame(origin)
    n = await upload_exclusions(drone, local, origin)
    north, east = latlon_to_ned(*site.origin_deg, *origin)
    say(f"mission: {n} building(s) uploaded as geofence exclusion zones (scenario origin at "
        f"N {north:.1f} E {east:.1f} m of the autopilot's local origin); setpoints kept "
        f"{local.margin_m:g} m clear of them")  # fmt: skip
    return local
