"""The buildings uploaded to the autopilot as geofence exclusion polygons (MAVSDK geofence plugin).

A user flying among buildings with PX4 would load their footprints as exclusion zones of the
autopilot's geofence, so the autopilot itself refuses to fly into them; the mission runner does the
same with the buildings it clamps its setpoints around (:mod:`mission.obstacles`). Footprints are
local NED (north, east, m); the geofence is geodetic, so they are placed with the local frame's
geodetic origin (from HOME_POSITION: its geodetic position minus its local offset) on a flat earth,
the same projection the autopilot uses over a few kilometres.
"""

from __future__ import annotations

import asyncio
import math
from typing import Any

from mission.obstacles import Obstacles
from mission.vehicle import CommandError

EARTH_RADIUS_M = 6_378_137.0


def ned_to_latlon(north_m: float, east_m: float, origin_lat_deg: float, origin_lon_deg: float) -> tuple[float, float]:
    """Flat-earth local NED (m) to latitude, longitude (deg) around a geodetic origin."""
    lat = origin_lat_deg + math.degrees(north_m / EARTH_RADIUS_M)
    lon = origin_lon_deg + math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(origin_lat_deg))))
    return lat, lon


def local_origin(home: dict[str, Any]) -> tuple[float, float]:
    """The local frame's geodetic origin (deg) from a HOME_POSITION's fields (degE7 and local m)."""
    lat0, lon0 = home["latitude"] * 1e-7, home["longitude"] * 1e-7
    # HOME_POSITION's x, y are home's position in the local frame: step back by them.
    lat, lon = ned_to_latlon(-float(home["x"]), -float(home["y"]), lat0, lon0)
    return lat, lon


async def upload_exclusions(drone: Any, obstacles: Obstacles, origin: tuple[float, float],
                            timeout_s: float = 10.0) -> int:  # fmt: skip
    """Upload every building footprint (grown by the obstacles' margin) as an EXCLUSION polygon;
    returns how many. CommandError when the autopilot refuses or does not answer."""
    from mavsdk.asyncio.plugins.geofence import GeofenceAsync
    from mavsdk.plugins.geofence import FenceType, GeofenceData, Point, Polygon

    polygons = []
    for b in obstacles.buildings:
        fp = b.footprint
        pts = [Point(*ned_to_latlon(float(n), float(e), *origin)) for n, e in fp]
        polygons.append(Polygon(pts, FenceType.EXCLUSION))
    try:
        await asyncio.wait_for(GeofenceAsync(drone).upload_geofence(GeofenceData(polygons, [])), timeout_s)
    except TimeoutError:
        raise CommandError(f"geofence upload: no answer within {timeout_s:g} s") from None
    except Exception as e:  # noqa: BLE001 - GeofenceError: the autopilot's reason
        raise CommandError(f"geofence upload: {e}") from None
    return len(polygons)
