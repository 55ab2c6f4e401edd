"""A review's flight plots: what the log holds about the flight itself, beside the wind.

Written from :class:`~review.flight.FlightData` as whole columns (:mod:`recording.flight_plots` for the
entity paths), decimated to the recording's rate (the first sample of each ``dt``-long bin):

    altitude   -down of the position [m, up, above the log's local origin]; the GPS altitude minus the
               origin's altitude (PX4 ref_alt, DataFlash ORGN), or, without one, moved to meet the
               position's altitude at the first fix
    velocity   NED ground velocity [m/s] (the estimator's input: local position, EKF, or GPS)
    attitude   roll, pitch, yaw [deg] of the attitude quaternion (3-2-1), yaw unwrapped
    battery    voltage [V], current [A], remaining [%] (each only where the log has it)
    gps        fix type and satellites; the fixes (fix type 2 or more) as a track on the map: north /
               east of the local origin when the log tells it, else of the first fix moved onto the
               position at that time (without positions: the first fix at the map's origin)
"""

from __future__ import annotations

import numpy as np

from recording.flight_plots import euler_deg
from recording.recorder import RunRecorder
from recording.style import AXES
from review.flight import FlightData, Series, geodetic_to_ned

#: GPS_FIX_TYPE of a fix with a horizontal position (2D or better).
FIX_2D = 2


def _dec(s: Series, dt: float) -> Series:
    """The first row of each ``dt``-long bin [s] of ``s`` (``s`` sorted)."""
    if not len(s):
        return s
    b = np.floor((s.t - s.t[0]) / dt).astype(np.int64)
    idx = np.concatenate(([0], np.nonzero(np.diff(b))[0] + 1))
    return Series(s.t[idx], s.v[idx], s.name)


def _position_at(fd: FlightData, t: float) -> np.ndarray | None:
    """The position [m, NED] at or just after time ``t`` [s], or None without positions."""
    p = fd.position
    if not len(p):
        return None
    return np.asarray(p.v[min(int(np.searchsorted(p.t, t)), len(p) - 1)], dtype=float)


def gps_local(fd: FlightData) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] (N,) and positions [m, NED] (N, 3) of the GPS fixes on the position's origin (see the
    module docstring); only fixes of type 2D or better with a latitude and longitude."""
    g = fd.gps
    if not len(g):
        return np.zeros(0), np.zeros((0, 3))
    fix = g.v[:, 3]
    ok = np.all(np.isfinite(g.v[:, :3]), axis=1) & (np.isnan(fix) | (fix >= FIX_2D))
    ok &= (g.v[:, 0] != 0.0) | (g.v[:, 1] != 0.0)
    t, v = g.t[ok], g.v[ok]
    if not len(t):
        return t, np.zeros((0, 3))
    if fd.gps_origin is not None:
        o = np.asarray(fd.gps_origin, dtype=float)
        ned = geodetic_to_ned(np.r_[o[0], v[:, 0]], np.r_[o[1], v[:, 1]], np.r_[o[2], v[:, 2]])[1:]
        return t, ned
    ned = geodetic_to_ned(v[:, 0], v[:, 1], v[:, 2])
    p0 = _position_at(fd, float(t[0]))
    return t, ned if p0 is None else ned + p0


def write_flight(rec: RunRecorder, fd: FlightData, dt: float) -> None:
    """The flight plots and the GPS track of ``fd`` (module docstring), rows every ``dt`` [s] at most."""
    col = rec.series_columns
    p = _dec(fd.position, dt)
    if len(p):
        col("flight/altitude/vehicle", p.t, -p.v[:, 2])
    v = _dec(fd.velocity, dt)
    for k, a in enumerate(AXES):
        if len(v):
            col(f"flight/velocity/{a}", v.t, v.v[:, k])
    q = _dec(fd.attitude, dt)
    if len(q):
        e = euler_deg(q.v)
        for k, a in enumerate(("roll", "pitch", "yaw")):
            col(f"flight/attitude/{a}", q.t, e[:, k])
    b = _dec(fd.battery, dt)
    if len(b):
        for k, (a, scale) in enumerate((("voltage", 1.0), ("current", 1.0), ("remaining", 100.0))):
            col(f"flight/battery/{a}", b.t, b.v[:, k] * scale)
    g = _dec(fd.gps, dt)
    if len(g):
        col("flight/gps/fix", g.t, g.v[:, 3])
        col("flight/gps/satellites", g.t, g.v[:, 4])
    t, ned = gps_local(fd)
    if len(t):
        idx = _dec(Series(t, ned), dt)
        col("flight/altitude/gps", idx.t, -idx.v[:, 2])
        rec.gps_track(float(t[0]), ned[:, :2])


__all__ = ["FIX_2D", "gps_local", "write_flight"]
