"""Test helper: a simulated flight as a real MAVLink stream (project dialect, packed and parsed).

:func:`record` flies a scenario in the lockstep simulator; :func:`autopilot_messages` turns it into
the messages an autopilot would send (message objects with their time, in time order), and
:func:`over_the_wire` packs them with a system/component id and parses the bytes back, as a
receiver on the link gets them. Rates: HEARTBEAT, EXTENDED_SYS_STATE, SYSTEM_TIME 1 Hz, the IMU every
``imu_every``-th sample (250 Hz / n), ATTITUDE_QUATERNION 50 Hz, LOCAL_POSITION_NED 10 Hz,
rotor speeds at the ESC rate (50 Hz) as ESC_STATUS, or as actuator outputs from the simulator's
TRUE rotor commands through an :class:`estimator.motor_output.OutputMap` (PX4 quad-X order).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimator.motor_output import OutputMap
from sitl.scenario import load_scenario
from sitl.simulation import T_POS, T_QUAT, T_ROTOR_CMD, T_VEL, T_WIND, Simulation
from vehicle.frames import quat_mul, quat_to_dcm
from wire.dialect import mavlink

RAD_S_TO_RPM = 60.0 / (2.0 * np.pi)


@dataclass
class Flight:
    truth: np.ndarray  # Simulation.truth_array(): one row per IMU sample
    imu: list  # (t, accel FRD, gyro FRD)
    esc: list  # (t, rotor speeds rad/s)

    def wind_between(self, t0: float, t1: float) -> np.ndarray:
        """Mean true wind (air-mass velocity NED, m/s) at the vehicle over [t0, t1] (s)."""
        t = self.truth[:, 0]
        return np.asarray(self.truth[(t >= t0) & (t <= t1), T_WIND].mean(axis=0))


def record(seconds: float, scenario: str = "paper-s1", seed: int = 3) -> Flight:
    sim = Simulation(load_scenario(scenario).with_duration(seconds), seed=seed, record_truth=True)
    sim.run(seconds)
    out = sim.drain()
    return Flight(sim.truth_array(), out["imu"], out["esc"])


def autopilot_messages(f: Flight, imu: str = "HIL_SENSOR", imu_every: int = 1, rotors: str = "ESC_STATUS",
                       outputs: OutputMap | None = None, t_offset: float = 0.0, mav_type: int = 2,
                       velocity: bool = True, heading_error_deg: float = 0.0,
                       mag_field: tuple[float, float, float] | None = None,
                       odometry_yaw_sigma_deg: float | None = None) -> list[tuple[float, Any]]:  # fmt: skip
    """(arrival time = simulation time s, message) in time order; ``t_offset`` shifts every time stamp
    the messages carry (another clock) but not the arrival time. ``heading_error_deg``: the published
    attitude is the true one turned by this much about NED down (an autopilot's heading error).
    ``mag_field`` (NED, gauss): the IMU messages carry the true field in body axes, and GLOBAL_POSITION_INT
    (1 Hz) PX4's default home; without it they carry no field (all zeros). ``odometry_yaw_sigma_deg``: ODOMETRY
    (10 Hz) states this heading 1-sigma, as PX4's carries EKF2's."""
    h = math.radians(heading_error_deg) / 2.0
    q_err = np.array([math.cos(h), 0.0, 0.0, math.sin(h)])
    out: list[tuple[float, Any]] = []
    esc_i = 0
    for k, (t, acc, gyr) in enumerate(f.imu):
        ts = t + t_offset
        us, ms = int(round(ts * 1e6)), int(round(ts * 1e3))
        row = f.truth[k]
        if k % 250 == 0:
            out.append((t, mavlink.MAVLink_heartbeat_message(mav_type, 12, 129, 0, 4, 3)))
            out.append((t, mavlink.MAVLink_extended_sys_state_message(0, 2)))  # in the air
            out.append((t, mavlink.MAVLink_system_time_message(1_700_000_000_000_000 + us, ms)))
            if mag_field is not None:
                out.append((t, mavlink.MAVLink_global_position_int_message(ms, 473977420, 85455940, 498000,
                                                                           10000, 0, 0, 0, 0)))  # fmt: skip
        while esc_i < len(f.esc) and f.esc[esc_i][0] <= t + 1e-9:
            if rotors == "ESC_STATUS":
                rpm = [int(round(w * RAD_S_TO_RPM)) for w in f.esc[esc_i][1]]
                out.append((t, mavlink.MAVLink_esc_status_message(0, us, rpm, [16.0] * 4, [5.0] * 4)))
            elif rotors in ("ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW"):
                assert outputs is not None
                raw = outputs.raw_outputs(row[T_ROTOR_CMD])
                if rotors == "ACTUATOR_OUTPUT_STATUS":
                    out.append((t, mavlink.MAVLink_actuator_output_status_message(us, 4, raw + [0.0] * 28)))
                else:
                    pwm = [int(round(v)) for v in raw] + [0] * 4
                    out.append((t, mavlink.MAVLink_servo_output_raw_message(us & 0xFFFFFFFF, 0, *pwm)))
            esc_i += 1
        if k % 5 == 0:
            q = quat_mul(q_err, row[T_QUAT])
            out.append((t, mavlink.MAVLink_attitude_quaternion_message(ms, *q, 0.0, 0.0, 0.0, [0.0] * 4)))
        if velocity and k % 25 == 0:
            p, v = row[T_POS], row[T_VEL]
            out.append((t, mavlink.MAVLink_local_position_ned_message(ms, *p, *v)))
            if odometry_yaw_sigma_deg is not None:
                pose = [0.01] * 21
                pose[20] = math.radians(odometry_yaw_sigma_deg) ** 2
                out.append((t, mavlink.MAVLink_odometry_message(us, 1, 2, *p, list(q), *v, 0.0, 0.0, 0.0, pose,
                                                                [0.01] * 21, 0, 0, 100)))  # fmt: skip
        if k % imu_every == 0:
            mb = [0.0, 0.0, 0.0] if mag_field is None else (quat_to_dcm(row[T_QUAT]).T @ mag_field).tolist()
            bits = 0x3F if mag_field is None else 0x1FF  # accel, gyro (+ mag)
            if imu == "HIL_SENSOR":
                m = mavlink.MAVLink_hil_sensor_message(us, *acc, *gyr, *mb, 1013.0, 0, 0, 20.0, bits, 0)
            elif imu == "HIGHRES_IMU":
                m = mavlink.MAVLink_highres_imu_message(us, *acc, *gyr, *mb, 1013.0, 0, 0, 20.0, bits, 0)
            else:  # SCALED_IMU / RAW_IMU: mG and mrad/s (ArduPilot)
                mg = [int(round(a / 9.80665 * 1000.0)) for a in acc]
                mr = [int(round(g * 1000.0)) for g in gyr]
                m = (mavlink.MAVLink_scaled_imu_message(ms, *mg, *mr, 0, 0, 0, 2000) if imu == "SCALED_IMU"
                     else mavlink.MAVLink_raw_imu_message(us, *mg, *mr, 0, 0, 0, 0, 2000))  # fmt: skip
            out.append((t, m))
    return out


def over_the_wire(streams: list[tuple[int, int, list[tuple[float, Any]]]], order: str = "time") -> list[Any]:
    """Pack every (system, component, messages) stream with its ids and parse the bytes back, interleaved
    in arrival order (``order="time"``) or one stream after the other (``"concat"``)."""
    tagged = []
    for n, (sysid, compid, msgs) in enumerate(streams):
        tx = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        tagged += [(t, n, i, m.pack(tx)) for i, (t, m) in enumerate(msgs)]
    if order == "time":
        tagged.sort(key=lambda x: (x[0], x[1], x[2]))
    rx = mavlink.MAVLink(None)
    out = []
    for _, _, _, frame in tagged:
        msgs = rx.parse_buffer(frame)
        out += msgs or []
    return out
