"""Read a PX4 ULog (``.ulg``) into :class:`~review.flight.FlightData` with ``pyulog``.

Topics (first instance of each; PX4 names and units, already SI and NED/FRD):

    sensor_combined         accelerometer_m_s2[3] (specific force, FRD), gyro_rad[3]; the sample
                            time is timestamp + accelerometer_timestamp_relative   -> imu
    vehicle_attitude        q[4] = [w, x, y, z], body FRD -> NED                   -> attitude
    vehicle_local_position  x, y, z, vx, vy, vz (NED)                  -> position, velocity
    sensor_gps / vehicle_gps_position  vel_n_m_s, vel_e_m_s, vel_d_m_s -> velocity (fallback)
    esc_status              esc[i].esc_rpm, esc_count                  -> rotor speeds
    actuator_outputs        output[0..3] (PWM us, or 0..1)   -> rotor commands without ESC data
    wind / wind_estimate    windspeed_north, windspeed_east  -> PX4's own wind estimate
    vehicle_land_detected   landed                           -> in-air segments
    vehicle_status          nav_state, arming_state          -> mode / arming text
    debug_key_value         key "CHEM", value                -> chemical reading (mg/m^3)
    logged messages         -> text

ESC and output numbers follow PX4's motor order (quad-X by default: 1 FR, 2 RL, 3 FL, 4 RR)
and are mapped to the project's rotor order. Times: ULog ``timestamp`` (microseconds since
boot) in seconds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pyulog import ULog

from review.flight import FlightData, Series, make_input, pwm_to_fraction, state_changes
from review.tlog import MOTOR_ORDERS

TOPICS = [
    "sensor_combined",
    "vehicle_attitude",
    "vehicle_local_position",
    "sensor_gps",
    "vehicle_gps_position",
    "esc_status",
    "actuator_outputs",
    "wind",
    "wind_estimate",
    "vehicle_land_detected",
    "vehicle_status",
    "debug_key_value",
]
#: PX4 vehicle_status.nav_state values -> names (vehicle_status.msg).
NAV_STATES = {
    0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "AUTO_MISSION", 4: "AUTO_LOITER", 5: "AUTO_RTL", 10: "ACRO",
    12: "DESCEND", 13: "TERMINATION", 14: "OFFBOARD", 15: "STAB", 17: "AUTO_TAKEOFF", 18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET", 20: "AUTO_PRECLAND", 21: "ORBIT", 22: "AUTO_VTOL_TAKEOFF",
}  # fmt: skip
#: ULog logging levels ('0'..'7', syslog) -> Rerun text levels.
LOG_LEVELS = {"EMERGENCY": "CRITICAL", "ALERT": "CRITICAL", "CRITICAL": "CRITICAL", "ERROR": "ERROR",
              "WARNING": "WARN", "NOTICE": "INFO", "INFO": "INFO", "DEBUG": "DEBUG"}  # fmt: skip


def _cols(d: dict[str, np.ndarray], names: list[str]) -> np.ndarray | None:
    """Stack columns (N, k) as float, or None when one is missing."""
    if not all(n in d for n in names):
        return None
    return np.column_stack([np.asarray(d[n], dtype=float) for n in names])


def _key_string(d: dict[str, np.ndarray], i: int) -> str:
    """A char[] field flattened by pyulog into key[0], key[1], ... -> str."""
    chars = []
    k = 0
    while f"key[{k}]" in d:
        c = int(d[f"key[{k}]"][i])
        if c == 0:
            break
        chars.append(chr(c & 0xFF))
        k += 1
    return "".join(chars)


def read_ulog(path: Path | str, motor_order: str = "quad-x", w_max_rad_s: float = 600.0) -> FlightData:
    """Decode a ``.ulg`` (see the module docstring).

    Args:
        path: the log.
        motor_order: ``"quad-x"`` (PX4, default) or ``"windseek"`` (ESC i = rotor i);
            ``"auto"`` means quad-x here.
        w_max_rad_s: rotor speed at full actuator output [rad/s] (rotor commands from outputs).
    """
    path = Path(path)
    if motor_order == "auto":
        motor_order = "quad-x"
    if motor_order not in MOTOR_ORDERS:
        raise ValueError(f"motor_order = {motor_order!r}: allowed values are auto, {', '.join(MOTOR_ORDERS)}")
    order = MOTOR_ORDERS[motor_order]
    try:
        ulog = ULog(str(path), TOPICS)
    except Exception as e:  # pyulog raises plain exceptions on a bad header
        raise ValueError(f"{path}: not a readable ULog ({e})") from e
    fd = FlightData(path=path, kind="ulog")
    sys_name = ulog.msg_info_dict.get("sys_name", "")
    ver = ulog.msg_info_dict.get("ver_sw_release") or ulog.msg_info_dict.get("ver_sw", "")
    fd.autopilot = " ".join(str(s) for s in (sys_name or "PX4", ver) if s != "").strip()
    data: dict[str, dict[str, np.ndarray]] = {}
    for ds in ulog.data_list:
        fd.counts[ds.name if ds.multi_id == 0 else f"{ds.name}[{ds.multi_id}]"] += len(ds.data["timestamp"])
        if ds.multi_id == 0 and ds.name not in data:
            data[ds.name] = ds.data
    if ulog.file_corruption:
        fd.notes.append("pyulog reports file corruption: data after it may be missing")
    if ulog.dropouts:
        fd.notes.append(f"{len(ulog.dropouts)} logger dropout(s), {sum(d.duration for d in ulog.dropouts)} ms in all")
    rows = []

    def t_of(d: dict[str, np.ndarray]) -> np.ndarray:
        return np.asarray(d["timestamp"], dtype=float) * 1e-6

    if (d := data.get("sensor_combined")) is not None:
        acc = _cols(d, [f"accelerometer_m_s2[{i}]" for i in range(3)])
        gyr = _cols(d, [f"gyro_rad[{i}]" for i in range(3)])
        if acc is not None:
            t = t_of(d) + np.asarray(d.get("accelerometer_timestamp_relative", 0.0), dtype=float) * 1e-6
            for k in range(len(t)):
                rows.append(make_input(t[k], "imu", (acc[k], None if gyr is None else gyr[k])))
            fd.sources["imu"] = "sensor_combined"
    if (d := data.get("vehicle_attitude")) is not None and (q := _cols(d, [f"q[{i}]" for i in range(4)])) is not None:
        t = t_of(d)
        rows += [make_input(t[k], "attitude", q[k]) for k in range(len(t))]
        fd.attitude = Series(t, q, "attitude")
        fd.sources["attitude"] = "vehicle_attitude"
    if (d := data.get("vehicle_local_position")) is not None:
        t = t_of(d)
        if (p := _cols(d, ["x", "y", "z"])) is not None:
            fd.position = Series(t, p, "position")
            fd.sources["position"] = "vehicle_local_position"
        if (v := _cols(d, ["vx", "vy", "vz"])) is not None:
            ok = np.all(np.isfinite(v), axis=1)
            if "v_xy_valid" in d:
                ok &= np.asarray(d["v_xy_valid"]) != 0
            rows += [make_input(t[k], "velocity", v[k]) for k in np.nonzero(ok)[0]]
            fd.sources["velocity"] = "vehicle_local_position"
    if "velocity" not in fd.sources:
        for name in ("sensor_gps", "vehicle_gps_position"):
            d = data.get(name)
            if d is not None and (v := _cols(d, ["vel_n_m_s", "vel_e_m_s", "vel_d_m_s"])) is not None:
                t = t_of(d)
                ok = np.asarray(d.get("vel_ned_valid", np.ones(len(t))), dtype=float) != 0
                rows += [make_input(t[k], "velocity", v[k]) for k in np.nonzero(ok)[0]]
                fd.sources["velocity"] = name
                break
    rot_rows: list[tuple[float, np.ndarray]] = []
    if (d := data.get("esc_status")) is not None and "esc[0].esc_rpm" in d:
        t = t_of(d)
        n_esc = np.asarray(d.get("esc_count", np.full(len(t), 4)), dtype=int)
        rpm = _cols(d, [f"esc[{i}].esc_rpm" for i in range(4)])
        if rpm is not None:
            for k in np.nonzero(n_esc >= 4)[0]:
                w = np.zeros(4)
                for i, r in enumerate(order):
                    w[r] = abs(rpm[k, i]) * (2.0 * np.pi / 60.0)
                rot_rows.append((t[k], w))
                rows.append(make_input(t[k], "rotors", w))
            if rot_rows:
                fd.sources["rotors"] = "esc_status"
    if not rot_rows and (d := data.get("actuator_outputs")) is not None:
        out = _cols(d, [f"output[{i}]" for i in range(4)])
        if out is not None:
            t = t_of(d)
            frac = pwm_to_fraction(out)
            for k in range(len(t)):
                w = np.zeros(4)
                for i, r in enumerate(order):
                    w[r] = frac[k, i] * w_max_rad_s
                rot_rows.append((t[k], w))
                rows.append(make_input(t[k], "rotor_cmd", w))
            fd.sources["rotor_cmd"] = "actuator_outputs"
    fd.rotors = Series.from_rows(rot_rows, "rotors", 4)
    for name in ("wind", "wind_estimate"):
        d = data.get(name)
        if d is not None and (w := _cols(d, ["windspeed_north", "windspeed_east"])) is not None:
            fd.autopilot_wind = Series(t_of(d), np.column_stack([w, np.full(len(w), np.nan)]), "autopilot")
            fd.sources["autopilot_wind"] = name
            break
    if (d := data.get("vehicle_land_detected")) is not None and "landed" in d:
        t = t_of(d)
        fd.in_air = state_changes([(float(t[k]), not bool(d["landed"][k])) for k in range(len(t))])
        fd.sources["in_air"] = "vehicle_land_detected"
    if (d := data.get("vehicle_status")) is not None:
        t = t_of(d)
        last_nav = last_arm = None
        for k in range(len(t)):
            if "nav_state" in d and int(d["nav_state"][k]) != last_nav:
                last_nav = int(d["nav_state"][k])
                fd.texts.append((float(t[k]), f"mode {NAV_STATES.get(last_nav, last_nav)}", "INFO"))
            if "arming_state" in d and int(d["arming_state"][k]) != last_arm:
                last_arm = int(d["arming_state"][k])
                fd.texts.append((float(t[k]), "armed" if last_arm == 2 else "disarmed", "INFO"))
    if (d := data.get("debug_key_value")) is not None and "value" in d:
        t = t_of(d)
        chem = [(float(t[k]), float(d["value"][k])) for k in range(len(t)) if _key_string(d, k) == "CHEM"]
        fd.chem = Series.from_rows(chem, "chem")
        if chem:
            fd.sources["chem"] = "debug_key_value CHEM"
    for m in ulog.logged_messages:
        fd.texts.append((m.timestamp * 1e-6, m.message, LOG_LEVELS.get(m.log_level_str(), "INFO")))
    fd.texts.sort(key=lambda r: r[0])
    fd.inputs = rows
    fd.sort_inputs()
    fd.notes.append(f"motor order: {motor_order}")
    return fd


__all__ = ["TOPICS", "read_ulog"]
