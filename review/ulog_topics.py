"""PX4 ULog topics -> the columns of :class:`~review.flight.FlightData`, a whole topic at a time.

Topics (first instance of each; PX4 names and units, already SI and NED/FRD):

    sensor_combined         accelerometer_m_s2[3] (specific force, FRD), gyro_rad[3]; the sample
                            time is timestamp + accelerometer_timestamp_relative   -> imu
    vehicle_attitude        q[4] = [w, x, y, z], body FRD -> NED                   -> attitude
    vehicle_local_position  x, y, z, vx, vy, vz (NED), *_valid flags   -> position (where z is valid:
                            the height check needs it), velocity (where v_xy is valid)
    sensor_gps / vehicle_gps_position  vel_n_m_s, vel_e_m_s, vel_d_m_s -> velocity (fallback)
    esc_status              esc[i].esc_rpm, esc_count                  -> rotor speeds
    actuator_outputs        output[0..3] (PWM us, or 0..1)   -> rotor commands without ESC data
    wind / wind_estimate    windspeed_north, windspeed_east  -> PX4's own wind estimate
    vehicle_land_detected   landed                           -> in-air segments
    vehicle_status          arming_state (2 = armed; 3 = armed with error before PX4 1.14),
                            nav_state                        -> in-air fallback, mode / arming text
    debug_key_value         key "CHEM", value                -> chemical reading (mg/m^3)
    battery_status          voltage_v [V], current_a [A], remaining [0..1] (-1: unknown) -> battery
    vehicle_gps_position / sensor_gps  latitude_deg, longitude_deg, altitude_msl_m (PX4 >= 1.14; before:
                            lat, lon [1e-7 deg], alt [mm]), fix_type, satellites_used -> gps
    vehicle_local_position  ref_lat, ref_lon [deg], ref_alt [m] where xy_global -> the GPS track's origin

ESC and output numbers follow PX4's motor order (quad-X by default: 1 FR, 2 RL, 3 FL, 4 RR) and are
mapped to the project's rotor order. Times: ULog ``timestamp`` (microseconds since boot) in seconds.
"""

from __future__ import annotations

import numpy as np

from review.flight import FlightData, Series, esc_to_rotors, outputs_to_rotors, state_changes

Topic = dict[str, np.ndarray]
#: PX4 vehicle_status.nav_state values -> names (vehicle_status.msg).
NAV_STATES = {
    0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "AUTO_MISSION", 4: "AUTO_LOITER", 5: "AUTO_RTL", 10: "ACRO",
    12: "DESCEND", 13: "TERMINATION", 14: "OFFBOARD", 15: "STAB", 17: "AUTO_TAKEOFF", 18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET", 20: "AUTO_PRECLAND", 21: "ORBIT", 22: "AUTO_VTOL_TAKEOFF",
}  # fmt: skip
ARMED_STATES = (2, 3)
#: uORB's "no relative time stamp" marker (sensor_combined.RELATIVE_TIMESTAMP_INVALID).
RELATIVE_TIMESTAMP_INVALID = 2147483647


def cols(d: Topic, names: list[str]) -> np.ndarray | None:
    """Stack columns (N, k) as float, or None when one is missing."""
    if not all(n in d for n in names):
        return None
    return np.column_stack([np.asarray(d[n], dtype=float) for n in names])


def t_of(d: Topic) -> np.ndarray:
    return np.asarray(d["timestamp"], dtype=float) * 1e-6


def imu_topic(fd: FlightData, d: Topic) -> None:
    acc = cols(d, [f"accelerometer_m_s2[{i}]" for i in range(3)])
    if acc is None:
        return
    gyr = cols(d, [f"gyro_rad[{i}]" for i in range(3)])
    rel = np.asarray(d.get("accelerometer_timestamp_relative", np.zeros(len(acc))), dtype=float)
    ok = rel != RELATIVE_TIMESTAMP_INVALID
    t = t_of(d) + rel * 1e-6
    gyr = np.full((len(acc), 3), np.nan) if gyr is None else gyr
    fd.imu = Series.of(t[ok], np.column_stack([acc, gyr])[ok], "imu")
    fd.sources["imu"] = "sensor_combined"
    fd.imu_notes.append(f"IMU from sensor_combined at {fd.imu.rate_hz:.1f} Hz")


def attitude_topic(fd: FlightData, d: Topic) -> None:
    q = cols(d, [f"q[{i}]" for i in range(4)])
    if q is not None:
        fd.attitude = Series.of(t_of(d), q, "attitude")
        fd.sources["attitude"] = "vehicle_attitude"


def local_position_topic(fd: FlightData, d: Topic) -> None:
    """Position where xy is valid, velocity where v_xy is valid (down NaN where v_z is not)."""
    t = t_of(d)
    p = cols(d, ["x", "y", "z"])
    if p is not None:
        ok = np.asarray(d.get("z_valid", np.ones(len(t))), dtype=bool)
        xy = np.asarray(d.get("xy_valid", np.ones(len(t))), dtype=bool)
        if not xy[ok].all():
            fd.notes.append(f"{int((~xy[ok]).sum())} of {int(ok.sum())} vehicle_local_position sample(s) without a "
                            "valid horizontal position (xy_valid = 0): drawn as logged (dead reckoning)")  # fmt: skip
        if ok.any():
            fd.position = Series.of(t[ok], p[ok], "position")
            fd.sources["position"] = "vehicle_local_position"
    v = cols(d, ["vx", "vy", "vz"])
    if v is not None:
        ok = np.all(np.isfinite(v[:, :2]), axis=1) & np.asarray(d.get("v_xy_valid", np.ones(len(t))), dtype=bool)
        v = v.copy()
        v[~np.asarray(d.get("v_z_valid", np.ones(len(t))), dtype=bool), 2] = np.nan
        fd.velocity = Series.of(t[ok], v[ok], "velocity")
        fd.sources["velocity"] = "vehicle_local_position"


def gps_velocity_topic(fd: FlightData, name: str, d: Topic) -> bool:
    v = cols(d, ["vel_n_m_s", "vel_e_m_s", "vel_d_m_s"])
    if v is None:
        return False
    t = t_of(d)
    ok = np.asarray(d.get("vel_ned_valid", np.ones(len(t))), dtype=bool)
    fd.velocity = Series.of(t[ok], v[ok], "velocity")
    fd.sources["velocity"] = name
    return True


def esc_topic(fd: FlightData, d: Topic, order: tuple[int, ...]) -> None:
    rpm = cols(d, [f"esc[{i}].esc_rpm" for i in range(4)])
    if rpm is None:
        return
    t = t_of(d)
    ok = np.asarray(d.get("esc_count", np.full(len(t), 4)), dtype=int) >= 4
    if ok.any():
        fd.rotors = Series.of(t[ok], esc_to_rotors(rpm[ok], order), "rotors")
        fd.sources["rotors"] = "esc_status"


def outputs_topic(fd: FlightData, d: Topic, order: tuple[int, ...], w_max: float) -> None:
    out = cols(d, [f"output[{i}]" for i in range(4)])
    if out is not None:
        fd.rotor_cmd = Series.of(t_of(d), outputs_to_rotors(out, order, w_max), "rotor_cmd")
        fd.sources["rotor_cmd"] = "actuator_outputs"


def wind_topic(fd: FlightData, name: str, d: Topic) -> bool:
    w = cols(d, ["windspeed_north", "windspeed_east"])
    if w is None:
        return False
    fd.autopilot_wind = Series.of(t_of(d), np.column_stack([w, np.full(len(w), np.nan)]), "autopilot")
    fd.sources["autopilot_wind"] = name
    return True


def status_topic(fd: FlightData, d: Topic, land_detector: bool) -> None:
    """Mode and arming texts; without a land detector, arming is the in-air state."""
    t = t_of(d)
    if "nav_state" in d:
        for tc, nav in state_runs(t, np.asarray(d["nav_state"], dtype=int)):
            fd.texts.append((tc, f"mode {NAV_STATES.get(nav, nav)}", "INFO"))
    if "arming_state" not in d:
        return
    armed = np.isin(np.asarray(d["arming_state"], dtype=int), ARMED_STATES)
    changes = state_changes(t, armed)
    fd.texts += [(tc, "armed" if a else "disarmed", "INFO") for tc, a in changes]
    if not land_detector:
        fd.in_air = changes
        fd.sources["in_air"] = "vehicle_status (armed)"
        if not armed.any():
            fd.notes.append("never armed (vehicle_status.arming_state) and no land detector: not airborne")


def state_runs(t: np.ndarray, v: np.ndarray) -> list[tuple[float, int]]:
    """(t, value) where an integer state changes (the first sample always)."""
    if not len(t):
        return []
    idx = np.concatenate(([0], np.nonzero(v[1:] != v[:-1])[0] + 1))
    return [(float(t[i]), int(v[i])) for i in idx]


def land_topic(fd: FlightData, d: Topic) -> bool:
    if "landed" not in d:
        return False
    fd.in_air = state_changes(t_of(d), np.asarray(d["landed"]) == 0)
    fd.sources["in_air"] = "vehicle_land_detected"
    return True


def chem_topic(fd: FlightData, d: Topic) -> None:
    """debug_key_value rows whose key (char[10], flattened by pyulog into key[0], key[1], ...) is "CHEM"."""
    if "value" not in d or "key[0]" not in d:
        return
    key = b"CHEM\0"
    width = sum(1 for k in range(len(key)) if f"key[{k}]" in d)
    chars = np.column_stack([np.asarray(d[f"key[{k}]"], dtype=np.int64) & 0xFF for k in range(width)])
    ok = np.all(chars == np.frombuffer(key[:width], dtype=np.uint8), axis=1)
    if ok.any():
        fd.chem = Series.of(t_of(d)[ok], np.asarray(d["value"], dtype=float)[ok], "chem")
        fd.sources["chem"] = "debug_key_value CHEM"


def battery_topic(fd: FlightData, d: Topic) -> None:
    """Voltage [V], current [A] and remaining charge [0..1]; PX4's -1 (and a voltage of 0) mean unknown."""
    v = cols(d, ["voltage_v", "current_a", "remaining"])
    if v is None:
        return
    v = v.copy()
    v[v[:, 0] <= 0.0, 0] = np.nan
    v[v[:, 1] < 0.0, 1] = np.nan  # PX4 logs -1 A when it measures no current
    v[v[:, 2] < 0.0, 2] = np.nan
    fd.battery = Series.of(t_of(d), v, "battery")
    fd.sources["battery"] = "battery_status"


def gps_topic(fd: FlightData, name: str, d: Topic) -> bool:
    """Fixes: latitude, longitude [deg], altitude [m AMSL], fix type, satellites (module docstring)."""
    pos = cols(d, ["latitude_deg", "longitude_deg", "altitude_msl_m"])
    if pos is None:
        raw = cols(d, ["lat", "lon", "alt"])
        if raw is None:
            return False
        pos = raw * np.array([1e-7, 1e-7, 1e-3])
    n = len(pos)
    fix = np.asarray(d.get("fix_type", np.full(n, np.nan)), dtype=float)
    sats = np.asarray(d.get("satellites_used", np.full(n, np.nan)), dtype=float)
    fd.gps = Series.of(t_of(d), np.column_stack([pos, fix, sats]), "gps")
    fd.sources["gps"] = name
    return True


def gps_origin(fd: FlightData, d: Topic) -> None:
    """The local position's origin (ref_lat, ref_lon [deg], ref_alt [m]) once xy_global is set."""
    ref = cols(d, ["ref_lat", "ref_lon", "ref_alt"])
    ok = np.asarray(d.get("xy_global", np.zeros(0)), dtype=bool)
    if ref is not None and len(ok) == len(ref) and ok.any():
        fd.gps_origin = tuple(float(x) for x in ref[np.nonzero(ok)[0][-1]])  # type: ignore[assignment]


__all__ = [
    "NAV_STATES",
    "battery_topic",
    "gps_origin",
    "gps_topic",
    "attitude_topic",
    "chem_topic",
    "cols",
    "esc_topic",
    "gps_velocity_topic",
    "imu_topic",
    "land_topic",
    "local_position_topic",
    "outputs_topic",
    "status_topic",
    "wind_topic",
]
