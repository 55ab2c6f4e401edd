"""The Earth's magnetic field at the scenario's home: the World Magnetic Model, as the autopilots assume it.

PX4's EKF2 and ArduPilot's EKF3 take the magnetic declination at their position from their own tables of
the World Magnetic Model (PX4: ``src/lib/world_magnetic_model``, WMM-2020 at 2024.4; ArduPilot:
``libraries/AP_Declination``, IGRF) and trust it: a simulated magnetometer whose field points elsewhere
is a heading error the autopilot cannot see, and a heading error rotates every wind estimate made with
its attitude (0.7 deg was 0.12 m/s across a 10 m/s wind). windseek's field was a fixed mid-European
vector (declination 4.09 deg) against PX4's 3.41 deg at PX4's default home; it is now the WMM's at the
home (``pygeomag``, WMM2025 at its epoch 2025.0: 3.42 deg, inclination 63.50 deg, 48,318 nT there;
ArduPilot's table reads 3.19 deg). A fixed epoch keeps runs reproducible whatever the date.

Units: gauss (1 gauss = 1e5 nT), NED; degrees; altitude in m above the ellipsoid (WMM's reference).
"""

from __future__ import annotations

from functools import lru_cache

#: Decimal year the field is evaluated at (WMM2025's epoch: no secular-variation extrapolation).
WMM_EPOCH = 2025.0


@lru_cache(maxsize=64)
def earth_field_ned_gauss(lat_deg: float, lon_deg: float, alt_m: float = 0.0) -> tuple[float, float, float]:
    """The main field (north, east, down) in gauss at a geodetic point, WMM2025 at :data:`WMM_EPOCH`."""
    from pygeomag import GeoMag  # imported here: only scenario parsing and the compass check need it

    r = GeoMag().calculate(glat=float(lat_deg), glon=float(lon_deg), alt=float(alt_m) / 1000.0, time=WMM_EPOCH)
    return (round(r.x * 1e-5, 6), round(r.y * 1e-5, 6), round(r.z * 1e-5, 6))
