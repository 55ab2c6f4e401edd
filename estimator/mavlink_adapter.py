"""MAVLink adapter: pymavlink messages in, filter inputs out; the estimate back out as WIND_COV.

Runs the same :class:`~estimator.ukf.WindEstimator` against the project's SITL
(``windseek sitl``) or a real PX4 / ArduPilot flight controller.

Inputs (the first message type seen of each group is used, so two sources never feed the
filter twice; all decoded to SI, FRD/NED):
- IMU (specific force m/s^2 + gyro rad/s): HIL_SENSOR, HIGHRES_IMU (SI already) or
  SCALED_IMU (mG, mrad/s). Each IMU message is one predict + accelerometer update.
- Attitude (body FRD -> NED): ATTITUDE_QUATERNION ([w, x, y, z] = q1..q4) or ATTITUDE
  (3-2-1 Euler). Their body rates are used only when the IMU message carries no gyro.
- Velocity (NED m/s): LOCAL_POSITION_NED, GLOBAL_POSITION_INT (cm/s) or GPS_RAW_INT
  (ground speed and course over ground: horizontal only). Treated as valid at their
  timestamp (an autopilot's EKF output is already delay-compensated).
- Rotor speeds (rad/s): ESC_STATUS (rpm, windseek dialect, ``index`` = first ESC of the
  message), or RAW_RPM (one sensor per message, no time stamp: the latest time seen is
  used). ESC_INFO carries no speed: its failure flags mark an ESC's telemetry as unusable.
  ``esc_to_rotor`` maps ESC numbers to the rotor order of ``vehicle.rotor_model`` (1 front
  right, 2 rear right, 3 rear left, 4 front left); the project's SITL uses that order, PX4's
  quad-X order (1 FR, 2 RL, 3 FL, 4 RR) is :data:`PX4_QUAD_X`.

Time: messages carry time_usec or time_boot_ms of the same (autopilot boot) clock; both
become seconds. Samples that go back in time are rejected by the estimator and counted.

Output: WIND_COV with wind_x/y/z = the air-mass velocity in NED (m/s, the MAVLink and PX4
convention, same as ours), var_horiz/var_vert (m^2/s^2), accuracies as 1-sigma (m/s).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from estimator.ukf import WindEstimator
from vehicle.frames import euler_to_quat
from wire.dialect import mavlink

RPM_TO_RAD_S = 2.0 * math.pi / 60.0
G0 = 9.80665
#: ESC number (0-based) -> rotor index (0-based) for the project's SITL: identity.
SITL_ORDER = (0, 1, 2, 3)
#: PX4 quad-X: motor 1 FR, 2 RL, 3 FL, 4 RR -> rotors FR(0), RR(1), RL(2), FL(3).
PX4_QUAD_X = (0, 2, 3, 1)

IMU_TYPES = ("HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU")
ATT_TYPES = ("ATTITUDE_QUATERNION", "ATTITUDE")
VEL_TYPES = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT")


def _time_s(msg: Any) -> float:
    if hasattr(msg, "time_usec"):
        return msg.time_usec * 1e-6
    return msg.time_boot_ms * 1e-3


class MavlinkWindAdapter:
    """Decode pymavlink messages into :class:`WindEstimator` inputs.

    Args:
        estimator: the filter to feed.
        esc_to_rotor: ESC index -> rotor index map (see module docstring).
        min_gps_fix: GPS_RAW_INT fixes below this fix_type (3 = 3D) are ignored.
    """

    def __init__(
        self, estimator: WindEstimator, esc_to_rotor: tuple[int, ...] = SITL_ORDER, min_gps_fix: int = 3
    ) -> None:
        self.est = estimator
        self.esc_to_rotor = tuple(esc_to_rotor)
        self.min_gps_fix = min_gps_fix
        self.sources: dict[str, str] = {}  # group -> message type in use
        self.counts: Counter[str] = Counter()
        self.t_last = 0.0
        self._rotors = np.full(4, np.nan)
        self._rotor_seen = np.zeros(4, dtype=bool)
        self._esc_failed = np.zeros(4, dtype=bool)
        self._rotor_t = -math.inf
        self._rates: np.ndarray | None = None

    def _claim(self, group: str, mtype: str) -> bool:
        # One source per group: the first type seen wins.
        return self.sources.setdefault(group, mtype) == mtype

    def handle(self, msg: Any) -> bool:
        """Feed one decoded pymavlink message. Returns True when the estimator took it."""
        mtype = msg.get_type()
        self.counts[mtype] += 1
        if hasattr(msg, "time_usec") or hasattr(msg, "time_boot_ms"):
            self.t_last = max(self.t_last, _time_s(msg))
        if mtype in IMU_TYPES:
            return self._claim("imu", mtype) and self._imu(msg, mtype)
        if mtype in ATT_TYPES:
            return self._claim("attitude", mtype) and self._attitude(msg, mtype)
        if mtype in VEL_TYPES:
            return self._claim("velocity", mtype) and self._velocity(msg, mtype)
        if mtype == "ESC_STATUS":
            return self._claim("rotors", mtype) and self._esc(msg.index, msg.rpm, _time_s(msg))
        if mtype == "RAW_RPM":
            return self._claim("rotors", mtype) and self._esc(msg.index, [msg.frequency], self.t_last)
        if mtype == "ESC_INFO":
            for i, flags in enumerate(msg.failure_flags):
                k = msg.index + i
                if k < len(self.esc_to_rotor):
                    self._esc_failed[self.esc_to_rotor[k]] = flags != 0
            return True
        return False

    def _imu(self, msg: Any, mtype: str) -> bool:
        t = _time_s(msg)
        if mtype == "SCALED_IMU":
            acc = np.array([msg.xacc, msg.yacc, msg.zacc]) * (G0 / 1000.0)
            gyr = np.array([msg.xgyro, msg.ygyro, msg.zgyro]) * 1e-3
        else:
            acc = np.array([msg.xacc, msg.yacc, msg.zacc], dtype=float)
            gyr = np.array([msg.xgyro, msg.ygyro, msg.zgyro], dtype=float)
        return self.est.imu(t, acc, gyr)

    def _attitude(self, msg: Any, mtype: str) -> bool:
        t = _time_s(msg)
        if mtype == "ATTITUDE_QUATERNION":
            q = np.array([msg.q1, msg.q2, msg.q3, msg.q4], dtype=float)
        else:
            vals = (msg.roll, msg.pitch, msg.yaw)
            if not all(math.isfinite(v) for v in vals):
                return self.est._reject("attitude:bad_value")
            q = euler_to_quat(*vals)
        return self.est.set_attitude(t, q)

    def _velocity(self, msg: Any, mtype: str) -> bool:
        t = _time_s(msg)
        if mtype == "LOCAL_POSITION_NED":
            return self.est.gnss_velocity(t, np.array([msg.vx, msg.vy, msg.vz], dtype=float))
        if mtype == "GLOBAL_POSITION_INT":
            return self.est.gnss_velocity(t, np.array([msg.vx, msg.vy, msg.vz], dtype=float) * 0.01)
        if msg.fix_type < self.min_gps_fix or msg.vel == 65535 or msg.cog == 65535:
            return False
        speed = msg.vel * 0.01
        cog = math.radians(msg.cog * 0.01)
        return self.est.gnss_velocity(t, np.array([speed * math.cos(cog), speed * math.sin(cog)]))

    def _esc(self, index: int, rpms: Sequence[float], t: float) -> bool:
        for i, rpm in enumerate(rpms):
            k = index + i
            if k < len(self.esc_to_rotor):
                r = self.esc_to_rotor[k]
                self._rotors[r] = float(rpm) * RPM_TO_RAD_S
                self._rotor_seen[r] = True
        # Push a complete set once per time stamp: RAW_RPM arrives one rotor per message with
        # no time of its own, so several messages share the latest time seen.
        if not self._rotor_seen.all() or self._esc_failed.any() or t <= self._rotor_t:
            return False
        self._rotor_t = t
        return self.est.set_rotor_speeds(t, self._rotors.copy())

    # ------------------------------------------------------------------ output
    def wind_cov(self, wind_alt_m: float = float("nan")) -> mavlink.MAVLink_wind_cov_message:
        """The current estimate as a WIND_COV message (air-mass velocity NED, m/s)."""
        e = self.est.estimate(advance_direction=False)
        C = e.cov_ned
        var_h = float(C[0, 0] + C[1, 1])
        var_v = float(C[2, 2])
        t_us = int(round((e.t if math.isfinite(e.t) else self.t_last) * 1e6))
        return mavlink.MAVLink_wind_cov_message(
            t_us,
            float(e.wind_ned[0]),
            float(e.wind_ned[1]),
            float(e.wind_ned[2]),
            var_h,
            var_v,
            float(wind_alt_m),
            math.sqrt(max(var_h, 0.0)),
            math.sqrt(max(var_v, 0.0)),
        )

    def run(self, connection: Any, publish_hz: float = 5.0, duration_s: float | None = None) -> None:
        """Read messages from a pymavlink connection (``mavutil.mavlink_connection``) and publish
        WIND_COV at ``publish_hz`` of message time, until ``duration_s`` of message time or EOF."""
        t0 = None
        next_pub = 0.0
        while True:
            msg = connection.recv_match(blocking=True, timeout=1.0)
            if msg is None:
                if getattr(connection, "_eof", False):
                    return
                continue
            if msg.get_type() == "BAD_DATA":
                continue
            self.handle(msg)
            if t0 is None and self.t_last > 0.0:
                t0 = self.t_last
            if self.est.t is not None and self.t_last >= next_pub:
                connection.mav.send(self.wind_cov())
                next_pub = self.t_last + 1.0 / publish_hz
            if duration_s is not None and t0 is not None and self.t_last - t0 >= duration_s:
                return
