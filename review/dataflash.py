"""Read an ArduPilot DataFlash binary log (``.bin``) into :class:`~review.flight.FlightData`.

Messages (ArduPilot's LogStructure; :mod:`review.df_tables` decodes whole types at once):

    IMU (instance 0)      AccX/Y/Z [m/s^2, FRD specific force], GyrX/Y/Z [rad/s]     -> imu
    ATT                   Roll, Pitch, Yaw [deg] (3-2-1)                             -> attitude
    XKF1 (core 0) / NKF1  VN, VE, VD [m/s NED], PN, PE, PD [m NED from the EKF origin] -> velocity, position
    GPS (fallback)        Spd [m/s], GCrs [deg], VZ [m/s down], Lat/Lng/Alt           -> velocity, position
    ESC (Instance 0-3)    RPM [rpm]                                                  -> rotor speeds
    RCOU                  C1..C4 [PWM us]                  -> rotor commands without ESC telemetry
    XKF2 (core 0) / NKF2  VWN, VWE [m/s]: the EKF's wind (air-mass velocity)  -> the autopilot's wind
    STAT                  isFlying (ArduPlane) -> in-air state; else ARM ArmState / Armed -> arming
    MSG, MODE             texts and mode changes; the first MSG names the firmware (ArduPlane V3.8.2)
    PARM                  Q_ENABLE (a QuadPlane), FRAME_CLASS (Copter) -> vehicle type
    BAT (instance 0)      Volt [V], Curr [A], RemPct [%] (newer logs)                -> battery
    GPS (instance 0)      Lat, Lng [deg], Alt [m AMSL], Status (GPS_FIX_TYPE), NSats -> gps
    ORGN (Type 0)         Lat, Lng [deg], Alt [m]: the EKF origin                    -> the GPS track's origin

A file that ends inside a message (a truncated log) is read up to it, with a warning, as for a tlog.

Times: TimeUS (boot clock, microseconds) in seconds. Motor order: quad-X (1 FR, 2 RL, 3 FL, 4 RR) as
for PX4; a QuadPlane's lift motors are outputs 5-8 (RCOU C5..C8), not 1-4: the summary's model line
says that the implied rotor speeds of such a vehicle are not its lift motors.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pymavlink import mavutil

from review.df_tables import DataFlashTables
from review.flight import (
    FlightData,
    Series,
    esc_to_rotors,
    euler_to_quat_rows,
    geodetic_to_ned,
    outputs_to_rotors,
    state_changes,
)
from review.tlog import motor_order_of

#: ArduPilot firmware name -> vehicle type words and MAV_TYPE (for mode names).
FIRMWARES = {"ArduPlane": ("fixed wing", 1), "ArduCopter": ("multicopter", 2), "ArduRover": ("rover", 10),
             "ArduSub": ("submarine", 12), "Blimp": ("airship", 7)}  # fmt: skip
#: Copter FRAME_CLASS -> words (1 quad, 2 hexa, 3 octa, ...).
FRAME_CLASSES = {1: "quadrotor", 2: "hexarotor", 3: "octorotor", 4: "octa-quad", 5: "Y6", 7: "tricopter"}


def _cols(tab: dict[str, np.ndarray], names: list[str]) -> np.ndarray | None:
    return np.column_stack([tab[n] for n in names]) if all(n in tab for n in names) else None


def _identity(fd: FlightData, T: DataFlashTables) -> int:
    """Firmware and vehicle type; returns the MAV_TYPE used for mode names."""
    msgs = T.get("MSG")
    texts = T.texts(msgs, "Message") if msgs is not None else []
    fw = next((s for s in texts if s.split(" ")[0] in FIRMWARES), "")
    fd.family = "ArduPilot"
    fd.autopilot = f"ArduPilot {' '.join(fw.split(' ')[:2])}".strip() if fw else "ArduPilot"
    name = fw.split(" ")[0] if fw else ""
    kind, mav_type = FIRMWARES.get(name, ("unknown", 2))
    params = _params(T)
    if name == "ArduPlane" and params.get("Q_ENABLE", 0.0) > 0:
        kind = "VTOL QuadPlane (fixed wing with lift motors)"
    elif name == "ArduCopter" and "FRAME_CLASS" in params:
        kind = FRAME_CLASSES.get(int(params["FRAME_CLASS"]), kind)
    fd.vehicle_type = kind
    return mav_type


def _params(T: DataFlashTables) -> dict[str, float]:
    tab = T.get("PARM")
    if tab is None:
        return {}
    return dict(zip(T.texts(tab, "Name"), (float(v) for v in tab["Value"]), strict=True))


def _imu_attitude(fd: FlightData, T: DataFlashTables) -> None:
    imu = T.first_instance("IMU", "I")
    if imu is not None and (a := _cols(imu, ["AccX", "AccY", "AccZ", "GyrX", "GyrY", "GyrZ"])) is not None:
        fd.imu = Series.of(T.time_s(imu), a, "imu")
        fd.sources["imu"] = "IMU"
        fd.imu_notes.append(f"IMU from IMU (instance 0, m/s^2, rad/s) at {fd.imu.rate_hz:.1f} Hz")
    att = T.get("ATT")
    if att is not None and (e := _cols(att, ["Roll", "Pitch", "Yaw"])) is not None:
        e = np.radians(e)
        fd.attitude = Series.of(T.time_s(att), euler_to_quat_rows(e[:, 0], e[:, 1], e[:, 2]), "attitude")
        fd.sources["attitude"] = "ATT"


def _navigation(fd: FlightData, T: DataFlashTables) -> None:
    """Velocity and position from the EKF (XKF1, else NKF1), else GPS."""
    for name in ("XKF1", "NKF1"):
        ekf = T.first_instance(name, "C")
        if ekf is not None and len(ekf.get("VN", ())):
            t = T.time_s(ekf)
            fd.velocity = Series.of(t, _cols(ekf, ["VN", "VE", "VD"]), "velocity")  # type: ignore[arg-type]
            fd.position = Series.of(t, _cols(ekf, ["PN", "PE", "PD"]), "position")  # type: ignore[arg-type]
            fd.sources["velocity"] = fd.sources["position"] = name
            return
    gps = T.first_instance("GPS", "I")
    if gps is None or "Spd" not in gps:
        return
    ok = gps["Status"] >= 3
    gps = {k: v[ok] for k, v in gps.items()}
    cog = np.radians(gps["GCrs"])
    v = np.column_stack([gps["Spd"] * np.cos(cog), gps["Spd"] * np.sin(cog), gps["VZ"]])
    t = T.time_s(gps)
    fd.velocity = Series.of(t, v, "velocity")
    fd.position = Series.of(t, geodetic_to_ned(gps["Lat"], gps["Lng"], gps["Alt"]), "position")
    fd.sources["velocity"] = fd.sources["position"] = "GPS"


def _rotors(fd: FlightData, T: DataFlashTables, order: tuple[int, ...], w_max: float) -> None:
    """ESC RPM of instances 0-3 held at instance 0's times; else RCOU C1..C4 as rotor commands."""
    esc = T.get("ESC")
    if esc is not None and "RPM" in esc and "Instance" in esc:
        t = T.time_s(esc)
        base = t[esc["Instance"] == 0]
        rpm = np.full((len(base), 4), np.nan)
        for i in range(4):
            sel = esc["Instance"] == i
            j = np.searchsorted(t[sel], base, side="right") - 1
            rpm[:, i] = np.where(j >= 0, esc["RPM"][sel][np.maximum(j, 0)] if sel.any() else np.nan, np.nan)
        ok = np.all(np.isfinite(rpm), axis=1)
        if ok.any():
            fd.rotors = Series.of(base[ok], esc_to_rotors(rpm[ok], order), "rotors")
            fd.sources["rotors"] = "ESC"
            return
    rc = T.get("RCOU")
    if rc is not None and (out := _cols(rc, ["C1", "C2", "C3", "C4"])) is not None:
        fd.rotor_cmd = Series.of(T.time_s(rc), outputs_to_rotors(out, order, w_max), "rotor_cmd")
        fd.sources["rotor_cmd"] = "RCOU"


def _wind(fd: FlightData, T: DataFlashTables) -> None:
    for name in ("XKF2", "NKF2"):
        tab = T.first_instance(name, "C")
        if tab is not None and (w := _cols(tab, ["VWN", "VWE"])) is not None and len(w):
            fd.autopilot_wind = Series.of(T.time_s(tab), np.column_stack([w, np.full(len(w), np.nan)]), "autopilot")
            fd.sources["autopilot_wind"] = f"{name} (VWN, VWE)"
            return


def _states(fd: FlightData, T: DataFlashTables, mav_type: int) -> None:
    """In-air state (STAT.isFlying, else arming), arming and mode texts, MSG texts."""
    stat, arm = T.get("STAT"), T.get("ARM")
    if stat is not None and "isFlying" in stat:
        fd.in_air = state_changes(T.time_s(stat), stat["isFlying"] != 0)
        fd.sources["in_air"] = "STAT (isFlying)"
    armed = (arm, "ArmState") if arm is not None and len(arm.get("ArmState", ())) else (stat, "Armed")
    if armed[0] is not None and armed[1] in armed[0]:
        changes = state_changes(T.time_s(armed[0]), armed[0][armed[1]] != 0)
        fd.texts += [(t, "armed" if a else "disarmed", "INFO") for t, a in changes]
        if "in_air" not in fd.sources:
            fd.in_air = changes
            fd.sources["in_air"] = f"{'ARM' if armed[1] == 'ArmState' else 'STAT'} (armed)"
    if (mode := T.get("MODE")) is not None and "ModeNum" in mode:
        names = mavutil.mode_mapping_bynumber(mav_type) or {}
        for t, m in zip(T.time_s(mode), mode["ModeNum"], strict=True):
            fd.texts.append((float(t), f"mode {names.get(int(m), int(m))}", "INFO"))
    if (msg := T.get("MSG")) is not None:
        fd.texts += [(float(t), s, "INFO") for t, s in zip(T.time_s(msg), T.texts(msg, "Message"), strict=True)]


def _instance0(T: DataFlashTables, name: str) -> dict[str, np.ndarray] | None:
    """Rows of instance 0 of a type (its instance column is Instance, Inst or I, by firmware version)."""
    t = T.get(name)
    col = next((c for c in ("Instance", "Inst", "I") if t is not None and c in t), None)
    return t if col is None else T.first_instance(name, col)


def _battery_gps(fd: FlightData, T: DataFlashTables) -> None:
    """Battery (BAT), GPS fixes (GPS) and the EKF origin (ORGN) for the recording's plots and map."""
    bat = _instance0(T, "BAT")
    if bat is not None and "Volt" in bat and len(bat["Volt"]):
        n = len(bat["Volt"])
        rem = bat["RemPct"] * 0.01 if "RemPct" in bat else np.full(n, np.nan)
        fd.battery = Series.of(T.time_s(bat), np.column_stack([bat["Volt"], bat.get("Curr", np.full(n, np.nan)),
                                                                rem]), "battery")  # fmt: skip
        fd.sources["battery"] = "BAT"
    gps = _instance0(T, "GPS")
    if gps is not None and all(k in gps for k in ("Lat", "Lng", "Alt", "Status")) and len(gps["Lat"]):
        sats = gps.get("NSats", np.full(len(gps["Lat"]), np.nan))
        v = np.column_stack([gps["Lat"], gps["Lng"], gps["Alt"], gps["Status"], sats])
        fd.gps = Series.of(T.time_s(gps), v, "gps")
        fd.sources["gps"] = "GPS"
    org = T.get("ORGN")
    if org is not None and all(k in org for k in ("Lat", "Lng", "Alt")) and len(org["Lat"]):
        i = int(np.nonzero(org["Type"] == 0)[0][0]) if "Type" in org and (org["Type"] == 0).any() else 0
        fd.gps_origin = (float(org["Lat"][i]), float(org["Lng"][i]), float(org["Alt"][i]))


def read_dataflash(path: Path | str, motor_order: str = "quad-x", w_max_rad_s: float = 600.0) -> FlightData:
    """Decode a DataFlash ``.bin`` (see the module docstring); ``motor_order`` ``auto`` means quad-x."""
    path = Path(path)
    motor_order, order = motor_order_of("quad-x" if motor_order == "auto" else motor_order, False)
    T = DataFlashTables(path)
    fd = FlightData(path=path, kind="dataflash", size_bytes=path.stat().st_size)
    fd.counts.update(T.counts())
    if T.printed:
        more = f" (and {len(T.printed) - 3} more such lines)" if len(T.printed) > 3 else ""
        fd.warnings.append("pymavlink: " + "; ".join(T.printed[:3]) + more)
    if T.cut_off():
        fd.warnings.append("the last message is cut off (a truncated log)")
    mav_type = _identity(fd, T)
    _imu_attitude(fd, T)
    _navigation(fd, T)
    _rotors(fd, T, order, w_max_rad_s)
    _wind(fd, T)
    _states(fd, T, mav_type)
    _battery_gps(fd, T)
    if T.undecodable:
        fd.notes.append("message types not decodable from their FMT: " + ", ".join(T.undecodable))
    fd.texts.sort(key=lambda r: r[0])
    fd.notes.append(f"motor order: {motor_order}")
    return fd


__all__ = ["read_dataflash"]
