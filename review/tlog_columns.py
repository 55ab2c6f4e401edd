"""Rows of a ``.tlog``'s messages (:mod:`review.tlog_collect`) -> the columns of :class:`FlightData`.

Units (MAVLink common.xml and ardupilotmega.xml):

- HIL_SENSOR, HIGHRES_IMU: m/s^2 and rad/s already. SCALED_IMU, SCALED_IMU2, SCALED_IMU3: mG and
  mrad/s. RAW_IMU: "raw" in general, but ArduPilot fills it exactly like SCALED_IMU (mG, mrad/s;
  the XML says so), so it is used only when the autopilot is ArduPilot.
- ATTITUDE: 3-2-1 Euler angles [rad]; ATTITUDE_QUATERNION q1..q4 = [w, x, y, z].
- LOCAL_POSITION_NED: m, m/s NED. GLOBAL_POSITION_INT: degE7, mm, cm/s NED. GPS_RAW_INT: degE7,
  mm, cm/s ground speed and cdeg course (horizontal velocity only).
- SYS_STATUS: voltage_battery mV (UINT16_MAX: unknown), current_battery cA and battery_remaining %
  (-1: unknown). GPS_RAW_INT also gives fix_type (GPS_FIX_TYPE) and satellites_visible (255: unknown).
- ESC_STATUS, ESC_TELEMETRY_1_TO_4 (ArduPilot): rpm. RAW_RPM: rpm, one sensor per message.
- SERVO_OUTPUT_RAW (port 0, servos 1-4), ACTUATOR_OUTPUT_STATUS (actuators 0-3): PWM us or 0..1.
- WIND_COV: air-mass velocity NED [m/s]. ArduPilot WIND: ``direction`` the wind comes from [deg],
  ``speed`` [m/s] and ``speed_z`` [m/s, NED down of the air-mass velocity]. ArduPilot fills
  ``speed`` with the 3-D length of its wind vector (``wind.length()``, GCS_MAVLink_Plane.cpp),
  though the XML says "in ground plane": the horizontal speed is sqrt(speed^2 - speed_z^2).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from review.flight import (
    FlightData,
    Series,
    esc_to_rotors,
    euler_to_quat_rows,
    geodetic_to_ned,
    outputs_to_rotors,
    state_changes,
    wind_from_direction,
)
from review.tlog_collect import Collected

G0 = 9.80665
#: IMU message types in order of preference at equal counts; their units (acc, gyro scale to SI).
IMU_SCALE = {"HIL_SENSOR": (1.0, 1.0), "HIGHRES_IMU": (1.0, 1.0), "SCALED_IMU": (G0 / 1000.0, 1e-3),
             "RAW_IMU": (G0 / 1000.0, 1e-3), "SCALED_IMU2": (G0 / 1000.0, 1e-3),
             "SCALED_IMU3": (G0 / 1000.0, 1e-3)}  # fmt: skip
ATT_TYPES = ("ATTITUDE_QUATERNION", "ATTITUDE")
VEL_TYPES = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT")
ROTOR_TYPES = ("ESC_STATUS", "ESC_TELEMETRY_1_TO_4", "RAW_RPM")
OUTPUT_TYPES = ("SERVO_OUTPUT_RAW", "ACTUATOR_OUTPUT_STATUS")
SIM_TRUTH_NAMES = ("TRUEWN", "TRUEWE", "TRUEWD")
LANDED_UNDEFINED, LANDED_IN_AIR, LANDED_LANDING = 0, 2, 4


def _arr(rows: list[tuple[Any, ...]], width: int) -> np.ndarray:
    """The first ``width`` fields of each row as a float array (N, width)."""
    return np.array([r[:width] for r in rows], dtype=float).reshape(-1, width)


def choose_sources(counts: dict[str, int], family: str) -> dict[str, str]:
    """One message type per input group: the most frequent IMU type (the primary one at about equal
    counts), for the other groups the first present in order of preference."""
    src: dict[str, str] = {}
    imu = [m for m in IMU_SCALE if counts.get(m) and (m != "RAW_IMU" or family == "ArduPilot")]
    if imu:  # the most frequent; within 5 % of it, the first in IMU_SCALE's order (the primary IMU)
        top = max(counts[m] for m in imu)
        src["imu"] = next(m for m in imu if counts[m] >= 0.95 * top)
    for group, types in (("attitude", ATT_TYPES), ("velocity", VEL_TYPES), ("position", VEL_TYPES),
                         ("rotors", ROTOR_TYPES), ("rotor_cmd", OUTPUT_TYPES)):  # fmt: skip
        m = next((m for m in types if counts.get(m)), None)
        if m is not None:
            src[group] = m
    if "rotors" in src:
        src.pop("rotor_cmd", None)
    return src


def imu_columns(fd: FlightData, col: Collected, src: str) -> None:
    """IMU rows -> fd.imu (specific force m/s^2 FRD, gyro rad/s FRD) and a note on its rate and units."""
    a = _arr(col.rows[src], 7)
    acc_k, gyr_k = IMU_SCALE[src]
    fd.imu = Series.of(a[:, 0], np.column_stack([a[:, 1:4] * acc_k, a[:, 4:7] * gyr_k]), "imu")
    units = "m/s^2, rad/s" if acc_k == 1.0 else "mG, mrad/s"
    fd.imu_notes.append(f"IMU from {src} ({units}) at {fd.imu.rate_hz:.1f} Hz")


def attitude_columns(fd: FlightData, col: Collected, src: str) -> None:
    if src == "ATTITUDE_QUATERNION":
        a = _arr(col.rows[src], 5)
        fd.attitude = Series.of(a[:, 0], a[:, 1:5], "attitude")
        return
    a = _arr(col.rows[src], 4)
    a = a[np.all(np.isfinite(a), axis=1)]
    fd.attitude = Series.of(a[:, 0], euler_to_quat_rows(a[:, 1], a[:, 2], a[:, 3]), "attitude")


def velocity_columns(fd: FlightData, col: Collected, src: str) -> None:
    """NED ground velocity [m/s]; GPS_RAW_INT gives only north/east (down NaN) and needs a 3-D fix."""
    a = _arr(col.rows[src], 7)
    if src == "LOCAL_POSITION_NED":
        v = a[:, 4:7]
    elif src == "GLOBAL_POSITION_INT":
        v = a[:, 4:7] * 0.01
    else:
        ok = (a[:, 1] >= 3) & (a[:, 5] != 65535) & (a[:, 6] != 65535)
        a = a[ok]
        speed, cog = a[:, 5] * 0.01, np.radians(a[:, 6] * 0.01)
        v = np.column_stack([speed * np.cos(cog), speed * np.sin(cog), np.full(len(a), np.nan)])
    fd.velocity = Series.of(a[:, 0], v, "velocity")


def position_columns(fd: FlightData, col: Collected, src: str) -> None:
    """Position [m, NED]: the local frame, else a flat earth around the first fix (GLOBAL_POSITION_INT:
    altitude above home, so down = -relative altitude)."""
    a = _arr(col.rows[src], 7)
    if src == "LOCAL_POSITION_NED":
        fd.position = Series.of(a[:, 0], a[:, 1:4], "position")
        return
    if src == "GLOBAL_POSITION_INT":
        p = geodetic_to_ned(a[:, 1] * 1e-7, a[:, 2] * 1e-7, a[:, 3] * 1e-3)
        if len(p):
            p[:, 2] = -a[:, 3] * 1e-3
    else:
        a = a[a[:, 1] >= 3]
        p = geodetic_to_ned(a[:, 2] * 1e-7, a[:, 3] * 1e-7, a[:, 4] * 1e-3)
    fd.position = Series.of(a[:, 0], p, "position")


def battery_gps_columns(fd: FlightData, col: Collected) -> None:
    """SYS_STATUS -> fd.battery (V, A, 0..1); GPS_RAW_INT -> fd.gps (deg, deg, m AMSL, fix type, satellites)."""
    if col.rows.get("SYS_STATUS"):
        a = _arr(col.rows["SYS_STATUS"], 4)
        v = np.column_stack([a[:, 1] * 1e-3, a[:, 2] * 1e-2, a[:, 3] * 1e-2])
        v[(a[:, 1] <= 0) | (a[:, 1] >= 65535), 0] = np.nan
        v[a[:, 2] < 0, 1] = np.nan
        v[a[:, 3] < 0, 2] = np.nan
        fd.battery = Series.of(a[:, 0], v, "battery")
        fd.sources["battery"] = "SYS_STATUS"
    if col.rows.get("GPS_RAW_INT"):
        a = _arr(col.rows["GPS_RAW_INT"], 8)
        sats = np.where(a[:, 7] == 255, np.nan, a[:, 7])
        fd.gps = Series.of(a[:, 0], np.column_stack([a[:, 2] * 1e-7, a[:, 3] * 1e-7, a[:, 4] * 1e-3, a[:, 1], sats]),
                           "gps")  # fmt: skip
        fd.sources["gps"] = "GPS_RAW_INT"


def _esc_failed_at(col: Collected, t: np.ndarray) -> np.ndarray:
    """True where the latest ESC_INFO before t flags a failure on any of ESCs 1-4 (their speeds are unusable)."""
    rows = col.rows.get("ESC_INFO") or []
    if not rows:
        return np.zeros(len(t), dtype=bool)
    ti = np.array([r[0] for r in rows])
    bad = np.array([any(f != 0 for f in r[2][: max(0, 4 - int(r[1]))]) for r in rows])
    k = np.searchsorted(ti, t, side="right") - 1
    return np.where(k >= 0, bad[np.maximum(k, 0)], False)


def rotor_columns(fd: FlightData, col: Collected, src: str, order: tuple[int, ...]) -> None:
    """Measured rotor speeds [rad/s] from ESC telemetry (rpm), in the rotor order."""
    if src == "RAW_RPM":  # one sensor per message: a complete set at each time all four are known
        rpm, seen, t_prev, rows = np.zeros(4), np.zeros(4, dtype=bool), -math.inf, []
        for t, idx, f in col.rows[src]:
            if 0 <= idx < 4:
                rpm[int(idx)], seen[int(idx)] = f, True
            if seen.all() and t > t_prev:
                rows.append((t, *rpm))
                t_prev = t
        a = _arr(rows, 5)
    elif src == "ESC_STATUS":
        a = _arr([(r[0], *r[2][:4]) for r in col.rows[src] if r[1] == 0], 5)
    else:
        a = _arr([(r[0], *r[1][:4]) for r in col.rows[src]], 5)
    failed = _esc_failed_at(col, a[:, 0])
    if failed.any():
        fd.notes.append(f"{int(failed.sum())} ESC sample(s) dropped: ESC_INFO flags a failure")
        a = a[~failed]
    fd.rotors = Series.of(a[:, 0], esc_to_rotors(a[:, 1:5], order), "rotors")


def output_columns(fd: FlightData, col: Collected, src: str, order: tuple[int, ...], w_max: float) -> None:
    """Rotor speeds implied by the outputs of motors 1-4 (PWM 1000-2000 us -> 0..w_max)."""
    if src == "SERVO_OUTPUT_RAW":
        a = _arr([r[:1] + r[2:6] for r in col.rows[src] if r[1] == 0], 5)
    else:
        a = _arr([(r[0], *r[1][:4]) for r in col.rows[src]], 5)
    fd.rotor_cmd = Series.of(a[:, 0], outputs_to_rotors(a[:, 1:5], order, w_max), "rotor_cmd")


def wind_columns(fd: FlightData, col: Collected, autopilot_component: int | None) -> None:
    """The autopilot's own wind: WIND_COV (NED air-mass velocity), else ArduPilot WIND."""
    if col.rows.get("WIND_COV"):
        a = _arr(col.rows["WIND_COV"], 4)
        fd.autopilot_wind = Series.of(a[:, 0], a[:, 1:4], "autopilot")
        fd.sources["autopilot_wind"] = "WIND_COV"
        if col.wind_components - {autopilot_component}:
            fd.sources["autopilot_wind"] += " (component " + ", ".join(map(str, sorted(col.wind_components))) + ")"
    elif col.rows.get("WIND"):
        a = _arr(col.rows["WIND"], 4)
        h = np.sqrt(np.maximum(a[:, 2] ** 2 - a[:, 3] ** 2, 0.0))
        fd.autopilot_wind = Series.of(a[:, 0], wind_from_direction(a[:, 1], h, a[:, 3]), "autopilot")
        fd.sources["autopilot_wind"] = "WIND"


def named_value_columns(fd: FlightData, col: Collected) -> None:
    """NAMED_VALUE_FLOAT ``CHEM`` (mg/m^3) and the SITL's ``TRUEWN/TRUEWE/TRUEWD`` (true wind, NED m/s)."""
    chem: list[tuple[float, float]] = []
    truth: dict[int, dict[str, float]] = {}
    for t, name, value, ms in col.rows.get("NAMED_VALUE_FLOAT", []):
        if name == "CHEM":
            chem.append((t, value))
        elif name in SIM_TRUTH_NAMES:
            truth.setdefault(ms, {})[name] = value
    if chem:
        a = _arr(chem, 2)
        fd.chem = Series.of(a[:, 0], a[:, 1], "chem")
        fd.sources["chem"] = "NAMED_VALUE_FLOAT CHEM"
    rows = [(ms * 1e-3, *(p[n] for n in SIM_TRUTH_NAMES)) for ms, p in truth.items() if len(p) == 3]
    if rows:
        a = _arr(rows, 4)
        fd.truth_wind = Series.of(a[:, 0], a[:, 1:4], "truth")
        fd.sources["truth"] = "NAMED_VALUE_FLOAT TRUEWN/TRUEWE/TRUEWD"


def in_air_columns(fd: FlightData, col: Collected) -> None:
    """In-air state: EXTENDED_SYS_STATE's landed state (in air or landing), else HEARTBEAT arming, else none."""
    rows = [r for r in col.rows.get("EXTENDED_SYS_STATE", []) if r[1] != LANDED_UNDEFINED]
    if rows:
        a = _arr(rows, 2)
        fd.in_air = state_changes(a[:, 0], (a[:, 1] == LANDED_IN_AIR) | (a[:, 1] == LANDED_LANDING))
        fd.sources["in_air"] = "EXTENDED_SYS_STATE"
    elif col.armed:
        a = _arr(col.armed, 2)
        fd.in_air = state_changes(a[:, 0], a[:, 1] != 0)
        fd.sources["in_air"] = "HEARTBEAT (armed)"


__all__ = [
    "battery_gps_columns",
    "IMU_SCALE",
    "attitude_columns",
    "choose_sources",
    "imu_columns",
    "in_air_columns",
    "named_value_columns",
    "output_columns",
    "position_columns",
    "rotor_columns",
    "velocity_columns",
    "wind_columns",
]
