"""MAVLink adapter for recorded logs: pymavlink messages in, filter inputs out; WIND_COV out.

``windseek review`` (``review/tlog.py``) replays a ``.tlog`` through :class:`MavlinkWindAdapter`.
Live consumers use :class:`estimator.live.LiveCore` instead (lock-on, input selection, ground
gate, clock resets, actuator outputs); both decode with ``estimator.mavlink_decode``.

Inputs (the first message type seen of each group is used, unless the caller sets ``sources``;
two sources never feed the filter twice; all decoded to SI, FRD/NED):
- IMU (specific force m/s^2 + gyro rad/s): HIL_SENSOR, HIGHRES_IMU (SI already) or
  SCALED_IMU (mG, mrad/s). Each IMU message is one predict + accelerometer update.
- Attitude (body FRD -> NED): ATTITUDE_QUATERNION ([w, x, y, z] = q1..q4) or ATTITUDE
  (3-2-1 Euler).
- Velocity (NED m/s): LOCAL_POSITION_NED, GLOBAL_POSITION_INT (cm/s) or GPS_RAW_INT
  (ground speed and course over ground: horizontal only). Treated as valid at their
  timestamp (an autopilot's EKF output is already delay-compensated).
- Rotor speeds (rad/s): ESC_STATUS (rpm, windseek dialect, ``index`` = first ESC of the
  message), ESC_TELEMETRY_1_TO_4 (ArduPilot's, no time stamp), or RAW_RPM (one sensor per
  message, no time stamp: the latest time seen is
  used). ESC_INFO carries no speed: its failure flags mark an ESC's telemetry as unusable.
  ``esc_to_rotor`` maps ESC numbers to the rotor order (``estimator.motor_output``:
  :data:`SITL_ORDER`, :data:`PX4_QUAD_X`).

Time: messages carry time_usec or time_boot_ms of the same (autopilot boot) clock; both
become seconds. Samples that go back in time are rejected by the estimator and counted.

Output (:func:`wind_cov_message`): WIND_COV with wind_x/y/z = the air-mass velocity in NED (m/s,
the MAVLink and PX4 convention, same as ours), var_horiz/var_vert (m^2/s^2), accuracies as
1-sigma (m/s).
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np

from estimator import mavlink_decode as dec
from estimator.motor_output import PX4_QUAD_X, SITL_ORDER
from estimator.ukf import WindEstimator
from wire.dialect import mavlink

__all__ = ["ATT_TYPES", "IMU_TYPES", "PX4_QUAD_X", "SITL_ORDER", "VEL_TYPES", "MavlinkWindAdapter",
           "wind_cov_message"]  # fmt: skip

IMU_TYPES = ("HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU")
ATT_TYPES = dec.PREFERENCE["attitude"]
VEL_TYPES = dec.PREFERENCE["velocity"]


def wind_cov_message(
    t_s: float, wind_ned: np.ndarray, cov_ned: np.ndarray, wind_alt_m: float = float("nan")
) -> mavlink.MAVLink_wind_cov_message:
    """WIND_COV for an estimate at time ``t_s`` (s, autopilot clock): air-mass velocity NED (m/s),
    var_horiz = var N + var E and var_vert ((m/s)^2), accuracies as their square roots (m/s)."""
    var_h = float(cov_ned[0, 0] + cov_ned[1, 1])
    var_v = float(cov_ned[2, 2])
    return mavlink.MAVLink_wind_cov_message(
        int(round(t_s * 1e6)),
        float(wind_ned[0]),
        float(wind_ned[1]),
        float(wind_ned[2]),
        var_h,
        var_v,
        float(wind_alt_m),
        math.sqrt(max(var_h, 0.0)),
        math.sqrt(max(var_v, 0.0)),
    )


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

    def _claim(self, group: str, mtype: str) -> bool:
        # One source per group: the first type seen wins.
        return self.sources.setdefault(group, mtype) == mtype

    def handle(self, msg: Any) -> bool:
        """Feed one decoded pymavlink message. Returns True when the estimator took it."""
        mtype = msg.get_type()
        self.counts[mtype] += 1
        t = dec.stamp_s(msg)
        if t is not None:
            self.t_last = max(self.t_last, t)
        est = self.est
        if mtype in IMU_TYPES:
            return self._claim("imu", mtype) and est.imu(t, *dec.imu(msg))  # type: ignore[arg-type]
        if mtype in ATT_TYPES:
            if not self._claim("attitude", mtype):
                return False
            q = dec.attitude(msg)
            return est._reject("attitude:bad_value") if q is None else est.set_attitude(t, q)  # type: ignore[arg-type]
        if mtype in VEL_TYPES:
            if not self._claim("velocity", mtype):
                return False
            v = dec.velocity(msg, self.min_gps_fix)
            return v is not None and est.gnss_velocity(t, v)  # type: ignore[arg-type]
        if mtype in ("ESC_STATUS", "ESC_TELEMETRY_1_TO_4", "RAW_RPM"):
            if not self._claim("rotors", mtype):
                return False
            index, speeds = dec.rotor_telemetry(msg)
            return self._esc(index, speeds, t if mtype == "ESC_STATUS" else self.t_last)  # type: ignore[arg-type]
        if mtype == "ESC_INFO":
            for i, flags in enumerate(msg.failure_flags):
                k = msg.index + i
                if k < len(self.esc_to_rotor):
                    self._esc_failed[self.esc_to_rotor[k]] = flags != 0
            return True
        return False

    def _esc(self, index: int, speeds: list[float], t: float) -> bool:
        for i, w in enumerate(speeds):
            k = index + i
            if k < len(self.esc_to_rotor):
                r = self.esc_to_rotor[k]
                self._rotors[r] = w
                self._rotor_seen[r] = True
        # Push a complete set once per time stamp: RAW_RPM arrives one rotor per message with
        # no time of its own, so several messages share the latest time seen.
        if not self._rotor_seen.all() or self._esc_failed.any() or t <= self._rotor_t:
            return False
        self._rotor_t = t
        return self.est.set_rotor_speeds(t, self._rotors.copy())

    def wind_cov(self, wind_alt_m: float = float("nan")) -> mavlink.MAVLink_wind_cov_message:
        """The current estimate as a WIND_COV message (air-mass velocity NED, m/s)."""
        e = self.est.estimate(advance_direction=False)
        return wind_cov_message(e.t if math.isfinite(e.t) else self.t_last, e.wind_ned, e.cov_ned, wind_alt_m)
