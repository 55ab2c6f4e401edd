"""MAVLink estimator inputs decoded to SI, FRD body / NED world: one place for every adapter.

Messages are pymavlink-like objects (``get_type()`` and fields as attributes). Each function
returns the time stamp on the autopilot's boot clock (s) and the value, or None when the message
carries nothing usable (a non-finite attitude, a GPS fix below 3-D, an unknown velocity).

Units on the wire (MAVLink common.xml, checked against ArduPilot's senders for RAW_IMU):

- HIL_SENSOR, HIGHRES_IMU: m/s^2 and rad/s, time_usec. SCALED_IMU: mG and mrad/s, time_boot_ms.
  RAW_IMU is "raw" in the XML; ArduPilot (the autopilot that sends it) fills it with mG and mrad/s
  (``accel * 1000 / GRAVITY_MSS``, ``gyro * 1000``) and a boot-time time_usec, decoded as such.
- ATTITUDE_QUATERNION: q1..q4 = [w, x, y, z] body FRD -> NED. ATTITUDE: roll, pitch, yaw (rad, 3-2-1).
- LOCAL_POSITION_NED: vx, vy, vz m/s. GLOBAL_POSITION_INT: cm/s. GPS_RAW_INT: vel cm/s and cog
  cdeg (horizontal only; 65535 = unknown).
- ESC_STATUS: rpm (project dialect, ``index`` = first ESC of the message); ESC_TELEMETRY_1_TO_4
  (ArduPilot's, ESCs 1-4 in its motor order): rpm, no time stamp; RAW_RPM: one sensor (``index``) per
  message, frequency in rpm, no time stamp.
- Magnetic field (the compass check, direction only): HIL_SENSOR and HIGHRES_IMU xmag..zmag in gauss,
  SCALED_IMU and RAW_IMU in mgauss (ArduPilot fills both with its calibrated field; PX4's SCALED_IMU is the
  raw sensor_mag before its calibration, not used); all zeros = none.
- Position (the compass check's World Magnetic Model): GLOBAL_POSITION_INT, GPS_RAW_INT (lat/lon degE7,
  alt mm), HOME_POSITION (latitude/longitude degE7, altitude mm).
- ACTUATOR_OUTPUT_STATUS: actuator[32] floats in the output driver's units (PX4: PWM us,
  1000-2000 in SITL/SIH); SERVO_OUTPUT_RAW: servo1..16_raw, PWM us. See ``motor_output``.

Time stamps above :data:`MAX_BOOT_TIME_S` are on a UNIX or GPS epoch (GPS_RAW_INT, RAW_IMU and
SERVO_OUTPUT_RAW may carry one), not the boot clock: :func:`boot_time_s` returns None for them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vehicle.frames import euler_to_quat

G0 = 9.80665  # m/s^2 per g (MAVLink mG)
MAV_AUTOPILOT_PX4 = 12
RPM_TO_RAD_S = 2.0 * math.pi / 60.0
#: A boot clock above this (s, ~116 days) is an epoch time stamp, not time since boot.
MAX_BOOT_TIME_S = 1e7

#: Input groups and their message types, best first (the best one streaming is used).
PREFERENCE: dict[str, tuple[str, ...]] = {
    "imu": ("HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU", "RAW_IMU"),
    "attitude": ("ATTITUDE_QUATERNION", "ATTITUDE"),
    "velocity": ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT"),
    "rotors": ("ESC_STATUS", "ESC_TELEMETRY_1_TO_4", "RAW_RPM", "ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW"),
}
#: Messages that carry the vehicle's geodetic position.
POSITION_TYPES = frozenset({"GLOBAL_POSITION_INT", "GPS_RAW_INT", "HOME_POSITION"})
#: Message type -> input group.
GROUP_OF: dict[str, str] = {m: g for g, names in PREFERENCE.items() for m in names}
#: Rotor-speed sources that are measured speeds (ESC telemetry).
MEASURED_TYPES = frozenset({"ESC_STATUS", "ESC_TELEMETRY_1_TO_4", "RAW_RPM"})
#: Rotor-speed sources that are commands (through the motor model), not measured speeds.
COMMAND_TYPES = frozenset({"ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW"})
#: Messages whose time stamp is the autopilot's boot clock (SERVO_OUTPUT_RAW's uint32 us wraps
#: after 71 min, GPS_RAW_INT's may be an epoch: neither is used to follow the clock).
BOOT_CLOCK_TYPES = frozenset({"HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU", "RAW_IMU", "ATTITUDE_QUATERNION",
                              "ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ESC_STATUS",
                              "ACTUATOR_OUTPUT_STATUS", "SYSTEM_TIME"})  # fmt: skip


def stamp_s(msg: Any) -> float | None:
    """The message's own time stamp in seconds (time_usec or time_boot_ms), or None."""
    if hasattr(msg, "time_usec"):
        return float(msg.time_usec) * 1e-6
    if hasattr(msg, "time_boot_ms"):
        return float(msg.time_boot_ms) * 1e-3
    return None


def boot_time_s(msg: Any) -> float | None:
    """The message's time on the autopilot's boot clock (s), or None (no stamp, or an epoch stamp)."""
    t = stamp_s(msg)
    return t if t is not None and 0.0 <= t < MAX_BOOT_TIME_S else None


def imu(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """(specific force FRD m/s^2, body rates FRD rad/s) of an IMU message."""
    acc = np.array([msg.xacc, msg.yacc, msg.zacc], dtype=float)
    gyr = np.array([msg.xgyro, msg.ygyro, msg.zgyro], dtype=float)
    if msg.get_type() in ("SCALED_IMU", "RAW_IMU"):
        return acc * (G0 / 1000.0), gyr * 1e-3
    return acc, gyr


def magnetometer(msg: Any, autopilot: int | None = None) -> np.ndarray | None:
    """Magnetic field FRD in gauss of an IMU message, or None when it carries none (all zeros, absent, not
    updated since the last message by its fields_updated bits) or not a calibrated one: PX4's (``autopilot``
    MAV_AUTOPILOT_PX4) SCALED_IMU / RAW_IMU carry ``sensor_mag`` as the sensor gave it, before PX4 applies its
    CAL_MAGn offsets, scales and rotation."""
    mtype = msg.get_type()
    if mtype in ("SCALED_IMU", "RAW_IMU") and autopilot == MAV_AUTOPILOT_PX4:
        return None
    if mtype in ("HIL_SENSOR", "HIGHRES_IMU") and not int(msg.fields_updated) & 0x1C0:
        return None  # the last sample again (the field is 50 Hz, the IMU 250 Hz): weighed once
    try:
        m = np.array([msg.xmag, msg.ymag, msg.zmag], dtype=float)
    except AttributeError:
        return None
    if not m.any():
        return None
    return m * 1e-3 if mtype in ("SCALED_IMU", "RAW_IMU") else m


def yaw_sigma(msg: Any) -> float | None:
    """The 1-sigma of the heading (rad) an ODOMETRY message states (pose_covariance's yaw-yaw entry, the 21st
    of its upper triangle; PX4 fills it with EKF2's variance), or None when it states none (NaN first)."""
    cov = msg.pose_covariance
    var = float(cov[20]) if len(cov) > 20 else math.nan
    return math.sqrt(var) if math.isfinite(float(cov[0])) and math.isfinite(var) and var > 0.0 else None


def position(msg: Any) -> tuple[float, float, float] | None:
    """(latitude deg, longitude deg, altitude m AMSL) of a position message, or None without a fix."""
    if msg.get_type() == "HOME_POSITION":
        return msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3
    if msg.get_type() == "GPS_RAW_INT" and msg.fix_type < 3:
        return None
    return msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3


def attitude(msg: Any) -> np.ndarray | None:
    """Attitude quaternion [w, x, y, z] body FRD -> NED, or None for non-finite Euler angles."""
    if msg.get_type() == "ATTITUDE_QUATERNION":
        return np.array([msg.q1, msg.q2, msg.q3, msg.q4], dtype=float)
    vals = (msg.roll, msg.pitch, msg.yaw)
    if not all(math.isfinite(v) for v in vals):
        return None
    return np.asarray(euler_to_quat(*vals), dtype=float)


def velocity(msg: Any, min_gps_fix: int = 3) -> np.ndarray | None:
    """NED ground velocity (m/s): 3 components, or 2 (north, east) from GPS_RAW_INT; None if unusable."""
    mtype = msg.get_type()
    if mtype == "LOCAL_POSITION_NED":
        return np.array([msg.vx, msg.vy, msg.vz], dtype=float)
    if mtype == "GLOBAL_POSITION_INT":
        return np.array([msg.vx, msg.vy, msg.vz], dtype=float) * 0.01
    if msg.fix_type < min_gps_fix or msg.vel == 65535 or msg.cog == 65535:
        return None
    speed = msg.vel * 0.01
    cog = math.radians(msg.cog * 0.01)
    return np.array([speed * math.cos(cog), speed * math.sin(cog)])


def rotor_telemetry(msg: Any) -> tuple[int, list[float]]:
    """(index of the first ESC, speeds in rad/s) of ESC_STATUS, ESC_TELEMETRY_1_TO_4 or RAW_RPM (rpm on the
    wire)."""
    mtype = msg.get_type()
    if mtype == "ESC_STATUS":
        return int(msg.index), [float(r) * RPM_TO_RAD_S for r in msg.rpm]
    if mtype == "ESC_TELEMETRY_1_TO_4":
        return 0, [float(r) * RPM_TO_RAD_S for r in msg.rpm]
    return int(msg.index), [float(msg.frequency) * RPM_TO_RAD_S]


def actuator_outputs(msg: Any) -> list[float]:
    """Raw actuator output values, output 1 first, of ACTUATOR_OUTPUT_STATUS or SERVO_OUTPUT_RAW
    (servo1..16; the caller keeps port 0, the MAIN outputs the motors are on)."""
    if msg.get_type() == "ACTUATOR_OUTPUT_STATUS":
        return [float(v) for v in msg.actuator]
    return [float(getattr(msg, f"servo{i}_raw", 0)) for i in range(1, 17)]
