"""Buildings in a MAVSDK mission (issue 20.4): the runner places a scenario's buildings in the
autopilot's local frame from HOME_POSITION, uploads them as geofence exclusion polygons (read back
from the SITL's own fence) and its supervisor keeps every setpoint clear of them, flying the surge
around the building, against the real windseek SITL and MAVSDK over UDP.

The building stands on the surge path of ``open-field-low`` (start (0, 0), source 60 m north). Its
scenario frame is deliberately not the SITL's: the site's origin is 100 m north of the SITL's
geodetic origin, so a runner that ignored the frames would put the fence 100 m off.
"""

from __future__ import annotations

import asyncio
import threading
import time

import numpy as np
import pytest
from link_support import free_port, running, udp_to

from mission.obstacles import Building, Obstacles
from mission.runners.fence import SiteBuildings, latlon_to_ned, ned_to_latlon
from mission.runners.mavsdk_runner import MissionConfig, run_mission
from mission.safety import SafetyLimits
from sitl.scenario import load_scenario

pytestmark = pytest.mark.e2e
pytest.importorskip("mavsdk")

#: The building in the SITL's frame (N 25..31, E -3..3 m, 20 m tall): right on the surge path.
FOOTPRINT_SITL = np.array([[25.0, -3.0], [31.0, -3.0], [31.0, 3.0], [25.0, 3.0]])
SITE_OFFSET_N = 100.0  # the site's origin lies this far north of the SITL's


def test_frames_round_trip() -> None:
    lat, lon = ned_to_latlon(123.4, -56.7, 47.4, 8.5)
    n, e = latlon_to_ned(lat, lon, 47.4, 8.5)
    assert abs(n - 123.4) < 1e-6 and abs(e + 56.7) < 1e-6


def test_mission_uploads_the_buildings_as_exclusions_and_never_enters_them() -> None:
    sc = load_scenario("open-field-low")
    home = sc.sensors.home
    site_origin = ned_to_latlon(SITE_OFFSET_N, 0.0, home.lat_deg, home.lon_deg)
    site = SiteBuildings(Obstacles([Building(FOOTPRINT_SITL - [SITE_OFFSET_N, 0.0], 20.0, "block")]), site_origin)
    port = free_port()
    lines: list[str] = []
    track: list[np.ndarray] = []
    with running([udp_to(port)], sc, speed=4.0) as link:
        stop = threading.Event()

        def watch() -> None:  # the true position, as the SITL flies it
            while not stop.is_set():
                track.append(np.array(link.sim.position, dtype=float))
                time.sleep(0.01)

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        limits = SafetyLimits(time_limit_s=80.0)
        cfg = MissionConfig(connect=f"udpin://127.0.0.1:{port}", strategy="surge-cast", wind="estimated",
                            limits=limits, speed_hint=4.0, say=lines.append, buildings=site)  # fmt: skip
        try:
            res = asyncio.run(asyncio.wait_for(run_mission(cfg), 150.0))
        finally:
            stop.set()
            watcher.join(2.0)
        fence = link.geofence
    print("\n".join(lines))
    # The fence the SITL holds: one exclusion polygon, exactly the building in the SITL's frame.
    assert len(fence.polygons) == 1 and not fence.circles
    poly, inclusion = fence.polygons[0]
    assert not inclusion
    assert np.allclose(poly, FOOTPRINT_SITL, atol=0.05), poly
    assert any("1 building(s) uploaded as geofence exclusion zones" in ln for ln in lines)
    # The supervisor met the building and the vehicle never entered it (nor the SITL's fence).
    assert res.clamped_setpoints > 0
    pts = np.array(track)
    inside = ((pts[:, 0] > 25.0) & (pts[:, 0] < 31.0) & (pts[:, 1] > -3.0) & (pts[:, 1] < 3.0))
    assert pts[:, 0].max() > 15.0  # it did fly toward the building
    assert not inside.any()
    # ... and around it: the supervisor's detour took it past the far face (north 31 m), 4 m clear.
    past = pts[pts[:, 0] > 31.0]
    print(f"furthest north {pts[:, 0].max():.1f} m")
    assert len(past) > 0
    near = (pts[:, 0] > 21.0) & (pts[:, 0] < 35.0)
    assert np.all(np.maximum(np.abs(pts[near, 1]) - 3.0, np.maximum(25.0 - pts[near, 0], pts[near, 0] - 31.0)) > 2.0)
    assert fence.breaches == 0
    assert res.landed and res.disarmed
