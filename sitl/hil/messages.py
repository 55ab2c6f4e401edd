"""The MAVLink messages windseek sends as PX4's simulator, and as the vehicle's sensor peripheral.

To PX4's simulator link (``simulator_mavlink``, PX4 ``SimulatorMavlink.cpp:350-500``):

- HIL_SENSOR (``id`` 0, the lockstep IMU: its ``time_usec`` sets PX4's clock): specific force
  (FRD, m/s^2, -9.81 on z at rest), rates (FRD, rad/s), magnetic field (FRD, gauss), absolute
  pressure (hPa), pressure altitude (m), temperature (deg C). ``fields_updated``: accel 0x7 and
  gyro 0x38 in every message; mag 0x1C0 and baro 0x1A00 (abs pressure, pressure altitude,
  temperature: PX4 uses a group only when all its bits are set) only when the magnetometer or
  barometer has a new sample, so PX4 sees each at its own rate (50 Hz by default).
- HIL_GPS: WGS-84 position (degE7, mm AMSL), NED velocity (cm/s), ground speed (cm/s), course
  (cdeg; 65535 below 0.1 m/s), ``eph``/``epv`` = the receiver's 1-sigma accuracy in cm (PX4 reads
  them as accuracy, ``eph * 1e-2`` m), fix type 3, satellites. Sent when the GNSS delivers a fix
  (10 Hz, after its latency; ``EKF2_GPS_DELAY`` says the latency). ``time_usec`` is UNIX time.
- HIL_STATE_QUATERNION: the truth (attitude, rates, position, velocity, airspeed, specific
  force in mG), at the rate PX4 asks for (it asks 200 Hz at connect); PX4 logs it as ground truth.

To the companion programs, through PX4's forwarding (see :mod:`sitl.hil.peripheral`):
ESC_STATUS (rotor speeds in rpm, windseek's rotor order, from the ESC sensor model), the
chemical reading (NAMED_VALUE_FLOAT ``CHEM``, mg/m^3) and the simulation-only true wind
(NAMED_VALUE_FLOAT ``TRUEWN/TRUEWE/TRUEWD``, m/s, NED: no real vehicle sends these).

Times: the HIL clock is the simulation time, ``time_usec = round(t * 1e6)`` (:func:`hil_time_us`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from sitl.world.kernel import T_POS, T_QUAT, T_RATES, T_SPECIFIC_FORCE, T_TIME, T_VEL, T_WIND
from sitl.world.sensors import BaroSample, GnssConfig, GnssSample, HomeConfig, MagSample, ned_to_geodetic
from wire.dialect import mavlink

HIL_ACCEL = 0x007
HIL_GYRO = 0x038
HIL_MAG = 0x1C0
HIL_BARO = 0x1A00  # abs_pressure (bit 9), pressure_alt (bit 11), temperature (bit 12)
RAD_S_TO_RPM = 60.0 / (2.0 * math.pi)
G0 = 9.80665


def hil_time_us(t: float) -> int:
    """The HIL clock (PX4's clock in lockstep) of simulation time ``t`` [s], in microseconds."""
    return int(round(t * 1e6))


def _i16(v: float) -> int:
    return int(max(-32768, min(32767, round(v))))


class HilSensor(NamedTuple):
    """HIL_SENSOR as a plain tuple in wire order (the one message of every lockstep step: building a
    pymavlink object for it costs more than packing it). Field names and units are pymavlink's;
    ``id`` is the sensor instance (0: the lockstep IMU). :class:`sitl.hil.frames.FrameEncoder` packs it."""

    time_usec: int
    xacc: float
    yacc: float
    zacc: float
    xgyro: float
    ygyro: float
    zgyro: float
    xmag: float
    ymag: float
    zmag: float
    abs_pressure: float
    diff_pressure: float
    pressure_alt: float
    temperature: float
    fields_updated: int
    id: int

    def get_type(self) -> str:
        return "HIL_SENSOR"


# How HilSensor goes on the wire (read by FrameEncoder): message id, CRC extra, payload struct (pymavlink's).
setattr(HilSensor, "WIRE", (mavlink.MAVLINK_MSG_ID_HIL_SENSOR, mavlink.MAVLink_hil_sensor_message.crc_extra,  # noqa: B010
                            mavlink.MAVLink_hil_sensor_message.unpacker))  # fmt: skip


def hil_sensor(imu: tuple[float, np.ndarray, np.ndarray], mag: MagSample | None, baro: BaroSample | None,
               mag_new: bool, baro_new: bool, sensor_id: int = 0) -> HilSensor:  # fmt: skip
    """One HIL_SENSOR from an IMU sample ``(t, specific force FRD, rates FRD)`` and the latest
    magnetometer / barometer samples (their bits set only when ``*_new``)."""
    t, acc, gyr = imu
    updated = HIL_ACCEL | HIL_GYRO
    m = (0.0, 0.0, 0.0)
    pres = palt = temp = 0.0
    if mag is not None:
        m = tuple(mag.field_gauss.tolist())
        if mag_new:
            updated |= HIL_MAG
    if baro is not None:
        pres, palt, temp = baro.pressure_pa / 100.0, baro.altitude_m, baro.temperature_c
        if baro_new:
            updated |= HIL_BARO
    a, g = acc.tolist(), gyr.tolist()
    return HilSensor(hil_time_us(t), a[0], a[1], a[2], g[0], g[1], g[2], *m, float(pres), 0.0, float(palt),
                     float(temp), updated, sensor_id)  # fmt: skip


def hil_gps(g: GnssSample, cfg: GnssConfig, unix0_us: int) -> Any:
    """One HIL_GPS from a delivered GNSS fix; ``unix0_us`` = UNIX time of simulation time 0 [us]."""
    v = g.vel_ned
    gs = math.hypot(float(v[0]), float(v[1]))
    cog = int(round(math.degrees(math.atan2(v[1], v[0])) % 360.0 * 100)) % 36000 if gs > 0.1 else 65535
    eph = max(1, min(65534, int(round(100 * cfg.pos_noise_h_m))))
    epv = max(1, min(65534, int(round(100 * cfg.pos_noise_v_m))))
    return mavlink.MAVLink_hil_gps_message(
        unix0_us + hil_time_us(g.t), 3, int(round(g.lat_deg * 1e7)), int(round(g.lon_deg * 1e7)),
        int(round(g.alt_m * 1000)), eph, epv, int(round(gs * 100)), _i16(v[0] * 100), _i16(v[1] * 100),
        _i16(v[2] * 100), cog, int(g.satellites), 0, 0,
    )  # fmt: skip


class HilStateQuaternion(NamedTuple):
    """HIL_STATE_QUATERNION as a plain tuple in wire order (50 Hz, every 5th lockstep step: a pymavlink
    object and its generic packing cost more than the values). Field names and units are pymavlink's, the
    quaternion spread over ``q1..q4`` (:attr:`attitude_quaternion` gives it as pymavlink does)."""

    time_usec: int
    q1: float
    q2: float
    q3: float
    q4: float
    rollspeed: float
    pitchspeed: float
    yawspeed: float
    lat: int
    lon: int
    alt: int
    vx: int
    vy: int
    vz: int
    ind_airspeed: int
    true_airspeed: int
    xacc: int
    yacc: int
    zacc: int

    @property
    def attitude_quaternion(self) -> list[float]:
        return [self.q1, self.q2, self.q3, self.q4]

    def get_type(self) -> str:
        return "HIL_STATE_QUATERNION"


setattr(HilStateQuaternion, "WIRE", (mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION,  # noqa: B010
                                     mavlink.MAVLink_hil_state_quaternion_message.crc_extra,
                                     mavlink.MAVLink_hil_state_quaternion_message.unpacker))  # fmt: skip


def hil_state_quaternion(row: np.ndarray, home: HomeConfig) -> HilStateQuaternion:
    """Ground truth from a truth row of the world (:mod:`sitl.world.kernel`: time, specific force FRD,
    rates FRD, position NED, velocity NED, attitude, wind NED, all at one IMU sample instant)."""
    r = row.tolist()  # plain floats: the same IEEE arithmetic as numpy's scalars, without their overhead
    lat, lon, alt = ned_to_geodetic(row[T_POS], home)
    air = float(np.linalg.norm(row[T_VEL] - row[T_WIND]))  # numpy's norm: the same value as before, bit for bit
    air_cm = max(0, min(65535, int(round(air * 100))))
    k = 1000.0 / G0  # m/s^2 -> mG
    f, v = r[T_SPECIFIC_FORCE], r[T_VEL]
    q1, q2, q3, q4 = r[T_QUAT]
    p, q, rr = r[T_RATES]
    return HilStateQuaternion(hil_time_us(r[T_TIME]), q1, q2, q3, q4, p, q, rr, int(round(lat * 1e7)),
                              int(round(lon * 1e7)), int(round(alt * 1000)), _i16(v[0] * 100), _i16(v[1] * 100),
                              _i16(v[2] * 100), air_cm, air_cm, _i16(f[0] * k), _i16(f[1] * k),
                              _i16(f[2] * k))  # fmt: skip


def esc_status(t: float, speeds_rad_s: np.ndarray) -> Any:
    """ESC_STATUS of measured rotor speeds (rad/s, windseek's rotor order -> ESC 1-4), rpm on the wire."""
    rpm = [int(round(float(w) * RAD_S_TO_RPM)) for w in speeds_rad_s]
    return mavlink.MAVLink_esc_status_message(0, hil_time_us(t), rpm, [0.0] * 4, [0.0] * 4)


def named_value(t: float, name: str, value: float) -> Any:
    """NAMED_VALUE_FLOAT at simulation time ``t`` (``time_boot_ms``)."""
    return mavlink.MAVLink_named_value_float_message(int(round(t * 1000)) & 0xFFFFFFFF, name.encode(), float(value))


def true_wind(t: float, wind_ned: np.ndarray) -> list[Any]:
    """The simulation-only TRUEWN/TRUEWE/TRUEWD values (m/s, air-mass velocity NED)."""
    return [named_value(t, n, float(w)) for n, w in zip(("TRUEWN", "TRUEWE", "TRUEWD"), wind_ned, strict=True)]


def heartbeat_peripheral() -> Any:
    """The peripheral's HEARTBEAT: a generic component that is not an autopilot."""
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GENERIC, mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                             mavlink.MAV_STATE_ACTIVE, 3)  # fmt: skip

