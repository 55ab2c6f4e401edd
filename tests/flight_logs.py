"""Test helper: what an autopilot would log of an identification flight, as a PX4 ULog or a MAVLink tlog.

The flight is an :class:`identify.flight_data.FlightData` flown in-process (:func:`identify.fly.world.fly`:
IMU at 250 Hz, ESC speeds, rotor-speed commands, the autopilot's velocity and attitude), written as PX4
writes and streams it, with PX4's types and rates:

- ULog (:func:`write_ulog`): ``sensor_combined`` at the IMU rate; ``vehicle_attitude`` and
  ``vehicle_local_position`` every ``nav_every``-th sample (50 Hz); ``esc_status`` (int32 rpm, ESC k =
  output k) every ``esc_every``-th sample (50 Hz); ``actuator_outputs`` (PWM floats through the
  vehicle's motor map) every sample, as PX4's high-rate logging profile; ``vehicle_land_detected``
  (in the air) and ``vehicle_status`` (armed, offboard, quadrotor) at 10 Hz.
- tlog (:func:`write_tlog`): HIGHRES_IMU at the IMU rate; ATTITUDE_QUATERNION and LOCAL_POSITION_NED
  (millisecond time stamps), ESC_STATUS and ACTUATOR_OUTPUT_STATUS at 50 Hz; HEARTBEAT (PX4,
  quadrotor, armed) and EXTENDED_SYS_STATE (in the air) at 1 Hz; records ``[8-byte big-endian UNIX
  usec][frame]`` as ground stations write them.

Times are the flight's plus ``t0_s`` of the autopilot's boot clock. Positions integrate the velocity from
``start_ned`` (the identification does not use them; they only have to be there).
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
from ulog_writer import UlogWriter

from estimator.motor_output import OutputMap
from identify.flight_data import FlightData
from wire.dialect import mavlink

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


def _positions(data: FlightData, start_ned: tuple[float, float, float]) -> np.ndarray:
    dt = np.diff(data.t, prepend=data.t[0])[:, None]
    return np.asarray(start_ned) + np.cumsum(data.velocity_ned * dt, axis=0)


def _outputs(data: FlightData, omap: OutputMap) -> np.ndarray:
    assert data.rotor_commands is not None
    return np.array([omap.raw_outputs(c) for c in data.rotor_commands])


def _ulog_formats(w: UlogWriter) -> None:
    w.info("sys_name", "PX4")
    w.format("sensor_combined", [
        ("uint64_t", 0, "timestamp"), ("float", 3, "gyro_rad"), ("uint32_t", 0, "gyro_integral_dt"),
        ("int32_t", 0, "accelerometer_timestamp_relative"), ("float", 3, "accelerometer_m_s2"),
        ("uint32_t", 0, "accelerometer_integral_dt"),
    ])  # fmt: skip
    w.format("vehicle_attitude", [("uint64_t", 0, "timestamp"), ("float", 4, "q")])
    w.format("vehicle_local_position", [("uint64_t", 0, "timestamp")] + [("float", 0, c) for c in
             ("x", "y", "z", "vx", "vy", "vz")] + [("bool", 0, c) for c in
             ("xy_valid", "z_valid", "v_xy_valid", "v_z_valid")])  # fmt: skip
    w.format("esc_report", [("uint64_t", 0, "timestamp"), ("int32_t", 0, "esc_rpm"), ("float", 0, "esc_voltage")])
    w.format("esc_status", [("uint64_t", 0, "timestamp"), ("uint8_t", 0, "esc_count"), ("esc_report", 8, "esc")])
    w.format("actuator_outputs", [("uint64_t", 0, "timestamp"), ("uint32_t", 0, "noutputs"), ("float", 16, "output")])
    w.format("vehicle_land_detected", [("uint64_t", 0, "timestamp"), ("bool", 0, "landed")])
    w.format("vehicle_status", [("uint64_t", 0, "timestamp"), ("uint8_t", 0, "arming_state"),
                                ("uint8_t", 0, "nav_state"), ("uint8_t", 0, "system_type")])  # fmt: skip


def write_ulog(path: Path, data: FlightData, omap: OutputMap, *, drop: frozenset[str] = frozenset(),
               t0_s: float = 100.0, nav_every: int = 5, esc_every: int = 5,
               start_ned: tuple[float, float, float] = (0.0, 0.0, -30.0),
               landed: tuple[float, float] | None = None) -> Path:  # fmt: skip
    """``data`` as a PX4 ULog at ``path`` (module docstring); topics in ``drop`` are left out; ``landed``:
    flight times (s) the land detector says landed (10 Hz) and the vehicle is disarmed."""
    w = UlogWriter(path)
    _ulog_formats(w)
    topics = [n for n in w.formats if n != "esc_report" and n not in drop]
    for name in topics:
        w.subscribe(name)
    pos = _positions(data, start_ned)
    raw = _outputs(data, omap) if "actuator_outputs" not in drop else None
    order = omap.order
    for k in range(data.n):
        us = int(round((t0_s + data.t[k]) * 1e6))
        if k % 25 == 0:
            down = landed is not None and landed[0] <= data.t[k] < landed[1]
            if "vehicle_land_detected" in topics:
                w.data("vehicle_land_detected", {"timestamp": us, "landed": down})
            if "vehicle_status" in topics:
                w.data("vehicle_status", {"timestamp": us, "arming_state": 1 if down else 2, "nav_state": 14,
                                          "system_type": 2})  # fmt: skip
        if "sensor_combined" in topics:
            w.data("sensor_combined", {"timestamp": us, "gyro_rad": data.rates[k], "gyro_integral_dt": 4000,
                                       "accelerometer_m_s2": data.specific_force[k],
                                       "accelerometer_integral_dt": 4000})  # fmt: skip
        if k % nav_every == 0:
            if "vehicle_attitude" in topics:
                w.data("vehicle_attitude", {"timestamp": us, "q": data.quaternion[k]})
            if "vehicle_local_position" in topics:
                p, v = pos[k], data.velocity_ned[k]
                w.data("vehicle_local_position", {"timestamp": us, "x": p[0], "y": p[1], "z": p[2], "vx": v[0],
                                                  "vy": v[1], "vz": v[2], "xy_valid": True, "z_valid": True,
                                                  "v_xy_valid": True, "v_z_valid": True})  # fmt: skip
        if k % esc_every == 0 and "esc_status" in topics:
            rpm = [int(round(data.rotor_speeds[k, order[i]] * RPM_PER_RAD_S)) for i in range(len(order))]
            w.data("esc_status", {"timestamp": us, "esc_count": len(order),
                                  "esc": [{"timestamp": us, "esc_rpm": r, "esc_voltage": 22.2} for r in rpm]})
        if raw is not None:
            w.data("actuator_outputs", {"timestamp": us, "noutputs": len(order), "output": raw[k]})
    w.close()
    return path


def _tlog_messages(data: FlightData, omap: OutputMap, t0_s: float, start_ned: tuple[float, float, float],
                   every: int) -> list[tuple[float, Any]]:  # fmt: skip
    out: list[tuple[float, Any]] = []
    pos = _positions(data, start_ned)
    raw = _outputs(data, omap)
    order = omap.order
    for k in range(data.n):
        t = t0_s + float(data.t[k])
        us, ms = int(round(t * 1e6)), int(round(t * 1e3))
        if k % 250 == 0:
            out.append((t, mavlink.MAVLink_heartbeat_message(2, 12, 129 | 8, 6 << 16, 4, 3)))
            out.append((t, mavlink.MAVLink_extended_sys_state_message(0, 2)))  # in the air
        a, g = data.specific_force[k], data.rates[k]
        out.append((t, mavlink.MAVLink_highres_imu_message(us, *a, *g, 0, 0, 0, 1013.0, 0, 0, 20.0, 0x3F, 0)))
        if k % every == 0:
            q, p, v = data.quaternion[k], pos[k], data.velocity_ned[k]
            out.append((t, mavlink.MAVLink_attitude_quaternion_message(ms, *q, 0.0, 0.0, 0.0, [0.0] * 4)))
            out.append((t, mavlink.MAVLink_local_position_ned_message(ms, *p, *v)))
            rpm = [int(round(data.rotor_speeds[k, order[i]] * RPM_PER_RAD_S)) for i in range(len(order))]
            out.append((t, mavlink.MAVLink_esc_status_message(0, us, rpm, [22.2] * 4, [5.0] * 4)))
            act = [float(x) for x in raw[k]] + [0.0] * (32 - len(order))
            out.append((t, mavlink.MAVLink_actuator_output_status_message(us, len(order), act)))
    return out


def write_tlog(path: Path, data: FlightData, omap: OutputMap, *, t0_s: float = 100.0, every: int = 5,
               start_ned: tuple[float, float, float] = (0.0, 0.0, -30.0)) -> Path:  # fmt: skip
    """``data`` as a MAVLink telemetry log at ``path`` (module docstring)."""
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    with path.open("wb") as f:
        for t, m in _tlog_messages(data, omap, t0_s, start_ned, every):
            f.write(struct.pack(">Q", int((1.7e9 + t) * 1e6)) + m.pack(tx))
    return path
