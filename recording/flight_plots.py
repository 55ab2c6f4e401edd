"""The flight's own time series (what PX4 Flight Review, Foxglove and PlotJuggler show first) and the
GPS track on the map.

Entity paths (SI; "up" is -down of NED; attitude in degrees for reading)::

    flight/altitude/{vehicle,gps}          altitude [m, up]: the vehicle's (the simulation's position, or
                                           a log's local position: above its origin) and the GPS altitude
                                           on the same origin (a review)
    flight/velocity/{north,east,down}      ground velocity [m/s, NED]
    flight/attitude/{roll,pitch,yaw}       3-2-1 Euler angles [deg]; yaw unwrapped (no +-180 deg jumps)
    flight/battery/{voltage,current,remaining}   [V], [A], [%]
    flight/gps/{fix,satellites}            GPS fix type (MAVLink GPS_FIX_TYPE: 3 = 3D) and satellites used
    map/gps                                the GPS fixes as one track (north up, like map/path)

A simulation (``recording.sim_hook``) writes only the altitude, at its series ticks but only when
it changed (:meth:`FlightPlotsMixin.altitude`): a trial recording's only per-sample addition. A
review (``review.rrd``) writes whole columns at once
(:meth:`FlightPlotsMixin.series_columns`).
"""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from recording.stream import ColumnBuffer, RecorderBase
from recording.style import C_AUTOPILOT, C_AXES3, C_GPS, C_TRUTH, Rgb

#: entity -> (legend name, colour) of every flight series.
FLIGHT_SERIES: dict[str, tuple[str, Rgb]] = {
    "flight/altitude/vehicle": ("position", C_TRUTH),
    "flight/altitude/gps": ("GPS", C_GPS),
    **{f"flight/velocity/{a}": (a, c) for a, c in zip(("north", "east", "down"), C_AXES3, strict=True)},
    **{f"flight/attitude/{a}": (a, c) for a, c in zip(("roll", "pitch", "yaw"), C_AXES3, strict=True)},
    "flight/battery/voltage": ("voltage", C_TRUTH),
    "flight/battery/current": ("current", C_TRUTH),
    "flight/battery/remaining": ("remaining", C_TRUTH),
    "flight/gps/fix": ("fix type (3 = 3D)", C_GPS),
    "flight/gps/satellites": ("satellites", C_AUTOPILOT),
}


#: A simulated altitude gets a row when it moved this far [m] or this long passed [s].
ALT_STEP_M = 0.05
ALT_GAP_S = 5.0


def euler_deg(q: np.ndarray) -> np.ndarray:
    """Quaternions [w, x, y, z] (N, 4), body FRD -> NED -> roll, pitch, yaw [deg] (N, 3), 3-2-1; yaw
    unwrapped (continuous, no jump at +-180 deg)."""
    q = np.asarray(q, dtype=float).reshape(-1, 4)
    w, x, y, z = q.T
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    ok = np.isfinite(yaw)
    yaw[ok] = np.unwrap(yaw[ok]) if ok.any() else yaw[ok]
    return np.degrees(np.column_stack([roll, pitch, yaw]))


class FlightPlotsMixin(RecorderBase):
    """Altitude, velocity, attitude, battery and GPS plots, and the GPS track (module docstring)."""

    scene_points: list[np.ndarray]

    _alt_last: tuple[float, float] | None = None  # (t [s], altitude [m]) of the last row written

    def altitude(self, t: float, up_m: float) -> None:
        """The vehicle's altitude [m, up] at vehicle time ``t`` [s]: a row only when it moved
        :data:`ALT_STEP_M` from the last row or :data:`ALT_GAP_S` passed (a hover or a level search
        adds few rows; the plot's straight lines between rows stay within about a step of the truth)."""
        t, up = float(t), float(up_m)
        last = self._alt_last
        if last is not None and abs(up - last[1]) < ALT_STEP_M and t - last[0] < ALT_GAP_S:
            return
        self._alt_last = (t, up)
        self._push("flight/altitude/vehicle", t, up)
        self._maybe_flush(t)

    def series_columns(self, entity: str, t: np.ndarray, v: np.ndarray) -> None:
        """Many rows of a scalar series at once: times [s] (N,), values (N,); non-finite values are gaps
        (left out). Sent with the other buffered rows (one ``send_columns`` per flush)."""
        t = np.asarray(t, dtype=float)
        v = np.asarray(v, dtype=float)
        ok = np.isfinite(t) & np.isfinite(v)
        if not ok.any():
            return
        buf = self._series.get(entity)
        if buf is None:
            buf = self._series[entity] = ColumnBuffer(rr.Scalars)
            buf.fields["scalars"] = []
        buf.t.extend(t[ok].tolist())
        buf.fields["scalars"].extend(v[ok].tolist())
        self._seen(float(t[ok].min()))
        self._seen(float(t[ok].max()))

    def gps_track(self, t: float, ne: np.ndarray) -> None:
        """The GPS fixes (N, 2) [m, north/east on the map's origin] as one track, logged at ``t`` [s]
        (the first fix: the whole track shows from then on); the map's extent includes it."""
        ne = np.asarray(ne, dtype=float).reshape(-1, 2)
        ne = ne[np.all(np.isfinite(ne), axis=1)]
        if len(ne) < 2 or not math.isfinite(t):
            return
        # Under the path (draw order 10): the fixes' scatter shows around the estimated path.
        self.log_at(t, "map/gps", rr.LineStrips2D([np.column_stack([ne[:, 1], -ne[:, 0]])], colors=[C_GPS],
                                                  radii=-1.0, draw_order=8.0, labels=["GPS"]))  # fmt: skip
        self.scene_points += [ne.min(axis=0), ne.max(axis=0)]


__all__ = ["ALT_GAP_S", "ALT_STEP_M", "FLIGHT_SERIES", "FlightPlotsMixin", "euler_deg"]
