"""What a flight log holds, decoded to the project's conventions: the common ground of the readers.

:class:`FlightData` is produced by :func:`review.tlog.read_tlog`, :func:`review.ulog.read_ulog` and
:func:`review.dataflash.read_dataflash`, and consumed by the estimator re-run, the summary and the
recording. Everything is SI, NED/FRD; wind is the air-mass velocity in NED (m/s); quaternions are
``[w, x, y, z]`` body FRD -> NED; rotor speeds are rad/s in the rotor order of
``vehicle.rotor_model`` (1 front right, 2 rear right, 3 rear left, 4 front left). Times are
seconds of the autopilot's boot clock (the project's SITL: simulation time), the same clock as the
log's own time stamps; the review's recording counts it from the log's start (:mod:`review.rrd`).

The data are columns (:class:`Series`, one array per quantity, sorted by time), so that a reader
converts a whole topic or message type at once and a 100 MB log costs no per-sample Python objects.
The estimator inputs are:

    imu         (N, 6): specific force [m/s^2, FRD] then gyro [rad/s, FRD] (NaN: no gyro)
    attitude    (N, 4): q [w, x, y, z], body FRD -> NED (held input)
    velocity    (N, 3): NED ground velocity [m/s] at its time of validity (NaN down: horizontal only)
    rotors      (N, 4): measured rotor speeds [rad/s] (held input; ESC telemetry)
    rotor_cmd   (N, 4): rotor speeds implied by the actuator outputs [rad/s] (through the motor lag)

Shown in the recording only (not estimator inputs):

    battery     (N, 3): voltage [V], current [A], remaining charge [0..1] (NaN: not in the log)
    gps         (N, 5): latitude [deg], longitude [deg], altitude above mean sea level [m], fix type
                (MAVLink GPS_FIX_TYPE: 0-1 no fix, 2 2D, 3 3D, 4 DGPS, 5 RTK float, 6 RTK fixed),
                satellites used (NaN: not in the log)
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Time stamps beyond this [s] are not on a boot clock (UNIX or GPS epoch): the readers drop them.
MAX_BOOT_TIME_S = 1.0e7


@dataclass
class Series:
    """A time series: t [s] (N,) sorted, and values (N,) or (N, k)."""

    t: np.ndarray
    v: np.ndarray
    name: str = ""

    @classmethod
    def empty(cls, width: int | None = None, name: str = "") -> Series:
        return cls(np.zeros(0), np.zeros((0,) if width is None else (0, width)), name)

    @classmethod
    def of(cls, t: np.ndarray, v: np.ndarray, name: str = "") -> Series:
        """From arrays: rows with a non-finite time are dropped, the rest sorted by time (stable)."""
        t = np.asarray(t, dtype=float)
        v = np.asarray(v, dtype=float)
        keep = np.isfinite(t)
        if not keep.all():
            t, v = t[keep], v[keep]
        if len(t) > 1 and np.any(np.diff(t) < 0.0):
            order = np.argsort(t, kind="stable")
            t, v = t[order], v[order]
        return cls(t, v, name)

    def __len__(self) -> int:
        return len(self.t)

    def between(self, t0: float, t1: float) -> Series:
        """The rows with t0 <= t <= t1 (a view)."""
        i, j = np.searchsorted(self.t, t0, side="left"), np.searchsorted(self.t, t1, side="right")
        return Series(self.t[i:j], self.v[i:j], self.name)

    @property
    def rate_hz(self) -> float:
        """Mean sample rate [Hz] (0 with fewer than two samples)."""
        if len(self.t) < 2 or self.t[-1] <= self.t[0]:
            return 0.0
        return float((len(self.t) - 1) / (self.t[-1] - self.t[0]))


def _empty(width: int | None = None, name: str = "") -> Series:
    return Series.empty(width, name)


@dataclass
class FlightData:
    """A decoded flight log (see the module docstring for units and frames).

    Attributes:
        path: the log file.
        kind: ``"tlog"``, ``"ulog"`` or ``"dataflash"``.
        autopilot: who wrote it, with its version when the log tells (``"PX4 v1.15.0 (dev)"``,
            ``"ArduPilot"``, ``"windseek SITL"``, ``"unknown"``).
        family: ``"PX4"``, ``"ArduPilot"``, ``"windseek SITL"`` or ``"unknown"``.
        vehicle_type: what the log says the vehicle is (``"quadrotor"``, ``"fixed wing"``,
            ``"VTOL ..."``, ``"unknown"``).
        counts: messages per MAVLink type / DataFlash type, or samples per ULog topic.
        sources: group (``imu``, ``attitude``, ``velocity``, ``rotors``, ``rotor_cmd``, ``position``,
            ``chem``, ``truth``, ``autopilot_wind``, ``in_air``) -> message type or topic it came
            from; a group that is absent was not in the log.
        imu, attitude, velocity, rotors, rotor_cmd: the estimator inputs (module docstring).
        position: vehicle position [m, NED] (N, 3), origin = the log's local origin (the first
            fix for logs with only global positions).
        chem: chemical reading [mg/m^3].
        truth_wind: simulation-only true wind at the vehicle (air-mass velocity NED, m/s).
        autopilot_wind: the autopilot's own wind estimate (air-mass velocity NED, m/s; down NaN
            when it has none).
        battery, gps: shown in the recording (module docstring), not used by the estimator.
        gps_origin: (latitude [deg], longitude [deg], altitude [m AMSL]) of :attr:`position`'s origin
            when the log tells it (PX4 ``vehicle_local_position.ref_*``, DataFlash ``ORGN``), else None.
        in_air: (t, in air?) state changes: landed state, else arming; empty when the log has
            neither (then the vehicle counts as never airborne).
        texts: (t, text, level) events: mode and arming changes, autopilot status texts.
        notes: reader remarks (dropped time stamps, undecodable frames, ...).
        warnings: problems with the file itself (corruption, truncation): shown on stderr too.
        imu_notes: remarks on the IMU (rate, units) that bear on the wind figure.
        not_airborne: why an in-air state was not taken as flight (:mod:`review.airborne`), or "".
        size_bytes: the file's size.
    """

    path: Path
    kind: str
    autopilot: str = "unknown"
    family: str = "unknown"
    vehicle_type: str = "unknown"
    counts: Counter[str] = field(default_factory=Counter)
    sources: dict[str, str] = field(default_factory=dict)
    imu: Series = field(default_factory=lambda: _empty(6, "imu"))
    attitude: Series = field(default_factory=lambda: _empty(4, "attitude"))
    velocity: Series = field(default_factory=lambda: _empty(3, "velocity"))
    rotors: Series = field(default_factory=lambda: _empty(4, "rotors"))
    rotor_cmd: Series = field(default_factory=lambda: _empty(4, "rotor_cmd"))
    position: Series = field(default_factory=lambda: _empty(3, "position"))
    chem: Series = field(default_factory=lambda: _empty(None, "chem"))
    truth_wind: Series = field(default_factory=lambda: _empty(3, "truth"))
    autopilot_wind: Series = field(default_factory=lambda: _empty(3, "autopilot"))
    battery: Series = field(default_factory=lambda: _empty(3, "battery"))
    gps: Series = field(default_factory=lambda: _empty(5, "gps"))
    gps_origin: tuple[float, float, float] | None = None
    in_air: list[tuple[float, bool]] = field(default_factory=list)
    texts: list[tuple[float, str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    imu_notes: list[str] = field(default_factory=list)
    not_airborne: str = ""
    size_bytes: int = 0

    def all_series(self) -> tuple[Series, ...]:
        return (self.imu, self.attitude, self.velocity, self.rotors, self.rotor_cmd, self.position, self.chem,
                self.truth_wind, self.autopilot_wind)  # fmt: skip

    def shown_series(self) -> tuple[Series, ...]:
        """Series only shown in the recording (battery, GPS): not in :attr:`time_range` or :attr:`has_data`."""
        return (self.battery, self.gps)

    @property
    def has_data(self) -> bool:
        """True when any time series was decoded (else the log gave nothing usable)."""
        return any(len(s) for s in self.all_series())

    @property
    def rotors_display(self) -> Series:
        """Rotor speeds to show: measured, else implied by the actuator outputs."""
        return self.rotors if len(self.rotors) else self.rotor_cmd

    @property
    def time_range(self) -> tuple[float, float]:
        """First and last time stamp [s] of any decoded data (NaN, NaN for an empty log)."""
        ts = [float(x) for s in self.all_series() if len(s) for x in (s.t[0], s.t[-1])]
        return (min(ts), max(ts)) if ts else (math.nan, math.nan)

    @property
    def duration_s(self) -> float:
        t0, t1 = self.time_range
        return 0.0 if not math.isfinite(t0) else t1 - t0

    def airborne_segments(self) -> list[tuple[float, float]]:
        """Time intervals [s] in the air, from :attr:`in_air`; none when that is unknown: a log
        that tells neither a landed state nor arming is not taken to be in the air."""
        t0, t1 = self.time_range
        if not math.isfinite(t0) or not self.in_air:
            return []
        segs: list[tuple[float, float]] = []
        start: float | None = None
        for t, air in sorted(self.in_air):
            if air and start is None:
                start = t
            elif not air and start is not None:
                segs.append((start, t))
                start = None
        if start is not None:
            segs.append((start, t1))
        # clipped to the data: a state change timed outside it must not add time nobody logged
        segs = [(max(a, t0), min(b, t1)) for a, b in segs]
        return [s for s in segs if s[1] > s[0]]


def state_changes(t: np.ndarray, state: np.ndarray) -> list[tuple[float, bool]]:
    """The samples where a boolean state changes (the first one always), as (t [s], state) pairs."""
    t = np.asarray(t, dtype=float)
    s = np.asarray(state, dtype=bool)
    if not len(t):
        return []
    order = np.argsort(t, kind="stable")
    t, s = t[order], s[order]
    idx = np.concatenate(([0], np.nonzero(s[1:] != s[:-1])[0] + 1))
    return [(float(t[i]), bool(s[i])) for i in idx]


def pwm_to_fraction(values: np.ndarray) -> np.ndarray:
    """Actuator outputs to a throttle fraction in [0, 1]: PWM in microseconds (1000-2000 us)
    when any value exceeds 100, otherwise already normalized (0..1)."""
    v = np.asarray(values, dtype=float)
    if np.nanmax(np.abs(v), initial=0.0) > 100.0:
        v = (v - 1000.0) / 1000.0
    return np.clip(v, 0.0, 1.0)


def outputs_to_rotors(out: np.ndarray, order: tuple[int, ...], w_max_rad_s: float) -> np.ndarray:
    """Actuator outputs (N, >=4) of motors 1-4 (PWM us or 0..1) -> implied rotor speeds (N, 4) [rad/s]
    in the rotor order (``order[i]`` = rotor of motor i + 1)."""
    frac = pwm_to_fraction(np.asarray(out, dtype=float)[:, :4])
    w = np.zeros((len(frac), 4))
    w[:, list(order)] = frac * w_max_rad_s
    return w


def esc_to_rotors(rpm: np.ndarray, order: tuple[int, ...]) -> np.ndarray:
    """ESC speeds (N, >=4) [rpm] of ESC 1-4 -> rotor speeds (N, 4) [rad/s] in the rotor order."""
    w = np.zeros((len(rpm), 4))
    w[:, list(order)] = np.abs(np.asarray(rpm, dtype=float)[:, :4]) * (2.0 * math.pi / 60.0)
    return w


def euler_to_quat_rows(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """3-2-1 Euler angles [rad] (N,) -> quaternions [w, x, y, z] (N, 4), body FRD -> NED
    (the same convention as ``vehicle.frames.euler_to_quat``, for whole columns)."""
    cr, sr = np.cos(0.5 * roll), np.sin(0.5 * roll)
    cp, sp = np.cos(0.5 * pitch), np.sin(0.5 * pitch)
    cy, sy = np.cos(0.5 * yaw), np.sin(0.5 * yaw)
    return np.column_stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])  # fmt: skip


def geodetic_to_ned(lat_deg: np.ndarray, lon_deg: np.ndarray, alt_m: np.ndarray) -> np.ndarray:
    """Positions (N,) on a flat earth around the first fix -> NED [m] (N, 3); altitude up -> down."""
    r_earth = 6_371_000.0
    if not len(lat_deg):
        return np.zeros((0, 3))
    lat0, lon0, alt0 = float(lat_deg[0]), float(lon_deg[0]), float(alt_m[0])
    n = np.radians(lat_deg - lat0) * r_earth
    e = np.radians(lon_deg - lon0) * r_earth * math.cos(math.radians(lat0))
    return np.column_stack([n, e, -(alt_m - alt0)])


def wind_from_direction(direction_deg: np.ndarray, speed_h: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Wind given as from-direction [deg] and horizontal speed [m/s] (+ down component) -> air-mass
    velocity NED (N, 3) [m/s]: air from the east (90 deg) moves west."""
    d = np.radians(direction_deg)
    return np.column_stack([-speed_h * np.cos(d), -speed_h * np.sin(d), down])


__all__ = [
    "MAX_BOOT_TIME_S",
    "FlightData",
    "Series",
    "esc_to_rotors",
    "euler_to_quat_rows",
    "geodetic_to_ned",
    "outputs_to_rotors",
    "pwm_to_fraction",
    "state_changes",
    "wind_from_direction",
]
