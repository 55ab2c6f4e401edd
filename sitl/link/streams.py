"""Message streams and their rates (SET_MESSAGE_INTERVAL, GET_MESSAGE_INTERVAL, REQUEST_MESSAGE).

Default rates follow PX4's ``onboard`` MAVLink mode, except the raw-sensor streams, which
follow the sensor that feeds them (noted below). Intervals are in simulation time, so at
``--speed K`` a 50 Hz stream arrives at 50 * K messages per wall-clock second.

A *periodic* stream samples the current state every interval. A *sample-driven* stream emits
one message per new sensor sample (HIL_SENSOR at the IMU rate, ESC_STATUS at the ESC
telemetry rate, GPS_RAW_INT per fix, CHEM per chemical reading); a longer interval decimates
it (a sample is sent when at least one interval has passed since the previous one sent).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from sitl.link.telemetry import Telemetry
from wire.dialect import mavlink


@dataclass
class Stream:
    name: str
    msg_id: int
    default_interval_s: float  # math.inf = not streamed unless requested
    build: Callable[..., list]
    samples: str | None = None  # name of the sensor queue that drives it
    interval_s: float = math.nan
    next_t: float = 0.0
    sent: int = 0

    def __post_init__(self) -> None:
        self.interval_s = self.default_interval_s


def _hz(rate: float) -> float:
    return 1.0 / rate


class StreamScheduler:
    """All outgoing streams of one endpoint, keyed by MAVLink message id."""

    def __init__(self, tel: Telemetry, true_wind_hz: float = 5.0) -> None:
        sim = tel.sim
        sens = sim.scenario.sensors
        M = mavlink
        specs: list[tuple[str, int, float, Callable[..., list], str | None]] = [
            ("HEARTBEAT", M.MAVLINK_MSG_ID_HEARTBEAT, 1.0, tel.heartbeat, None),
            ("SYS_STATUS", M.MAVLINK_MSG_ID_SYS_STATUS, _hz(5), tel.sys_status, None),
            ("EXTENDED_SYS_STATE", M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, _hz(5), tel.extended_sys_state, None),
            ("ATTITUDE", M.MAVLINK_MSG_ID_ATTITUDE, _hz(100), tel.attitude, None),
            ("ATTITUDE_QUATERNION", M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, _hz(50), tel.attitude_quaternion, None),
            ("LOCAL_POSITION_NED", M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, _hz(30), tel.local_position_ned, None),
            ("GLOBAL_POSITION_INT", M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, _hz(50), tel.global_position_int, None),
            ("HOME_POSITION", M.MAVLINK_MSG_ID_HOME_POSITION, _hz(0.5), tel.home_position, None),
            ("VFR_HUD", M.MAVLINK_MSG_ID_VFR_HUD, _hz(10), tel.vfr_hud, None),
            ("BATTERY_STATUS", M.MAVLINK_MSG_ID_BATTERY_STATUS, _hz(1), tel.battery_status, None),
            ("ALTITUDE", M.MAVLINK_MSG_ID_ALTITUDE, _hz(10), tel.altitude, None),
            ("HIGHRES_IMU", M.MAVLINK_MSG_ID_HIGHRES_IMU, _hz(50), tel.highres_imu, None),
            ("SERVO_OUTPUT_RAW", M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, _hz(10), tel.servo_output_raw, None),
            ("ACTUATOR_OUTPUT_STATUS", M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS, _hz(10), tel.actuator_output_status,
             None),
            ("ESC_INFO", M.MAVLINK_MSG_ID_ESC_INFO, _hz(1), tel.esc_info, None),
            ("RAW_RPM", M.MAVLINK_MSG_ID_RAW_RPM, _hz(5), tel.raw_rpm, None),
            ("SYSTEM_TIME", M.MAVLINK_MSG_ID_SYSTEM_TIME, _hz(1), tel.system_time, None),
            ("TIMESYNC", M.MAVLINK_MSG_ID_TIMESYNC, _hz(1), tel.timesync, None),
            ("MISSION_CURRENT", M.MAVLINK_MSG_ID_MISSION_CURRENT, _hz(1), tel.mission_current, None),
            # Sample-driven: the sensor's own rate (IMU 250 Hz, ESC 50 Hz, GNSS 10 Hz).
            ("HIL_SENSOR", M.MAVLINK_MSG_ID_HIL_SENSOR, _hz(sens.imu.rate_hz), tel.hil_sensor, "imu"),
            ("ESC_STATUS", M.MAVLINK_MSG_ID_ESC_STATUS, _hz(sens.esc.rate_hz), tel.esc_status, "esc"),
            ("GPS_RAW_INT", M.MAVLINK_MSG_ID_GPS_RAW_INT, _hz(sens.gnss.rate_hz), tel.gps_raw_int, "gnss"),
            # NAMED_VALUE_FLOAT carries both CHEM (per reading) and the debug true wind; the
            # message id selects the CHEM stream, the true wind has its own rate knob.
            ("NAMED_VALUE_FLOAT", M.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT, 0.0, tel.chem, "chem"),
        ]
        self.tel = tel
        self.streams: dict[int, Stream] = {}
        for name, mid, interval, build, samples in specs:
            self.streams[mid] = Stream(name, mid, interval, build, samples)
        self.true_wind = Stream("TRUEW", -1, _hz(true_wind_hz) if true_wind_hz > 0 else math.inf, tel.true_wind)
        # Messages that exist only on request (REQUEST_MESSAGE) are handled by the caller.

    def set_interval(self, msg_id: int, interval_us: float, now: float) -> bool:
        """SET_MESSAGE_INTERVAL: -1 stops, 0 restores the default, > 0 sets (us). False if unknown."""
        s = self.streams.get(int(msg_id))
        if s is None or not math.isfinite(interval_us):
            return False
        if interval_us < 0:
            s.interval_s = math.inf
        elif interval_us == 0:
            s.interval_s = s.default_interval_s
        else:
            s.interval_s = max(interval_us * 1e-6, 1e-4)
        s.next_t = now
        return True

    def interval_us(self, msg_id: int) -> int | None:
        """GET_MESSAGE_INTERVAL answer: interval in us, -1 if off, None if unknown."""
        s = self.streams.get(int(msg_id))
        if s is None:
            return None
        return -1 if math.isinf(s.interval_s) else int(round(s.interval_s * 1e6))

    def build_once(self, msg_id: int) -> list | None:
        """REQUEST_MESSAGE for a streamed message: one message now, None if unknown/no data."""
        s = self.streams.get(int(msg_id))
        if s is None:
            return None
        if s.samples is None:
            return s.build()
        latest = self.tel.latest.get(s.samples)
        return None if latest is None else s.build(latest)

    def due(self, now: float, samples: dict[str, list]) -> list:
        """Messages due at simulation time ``now`` given the samples produced since the last call."""
        out: list = []
        eps = 1e-6
        for s in self.streams.values():
            if math.isinf(s.interval_s):
                continue
            if s.samples is None:
                if now + eps >= s.next_t:
                    out.extend(s.build())
                    s.sent += 1
                    s.next_t += s.interval_s
                    if s.next_t <= now:  # fell behind (or first call): re-anchor, no bursts
                        s.next_t = now + s.interval_s
                continue
            for sample in samples.get(s.samples, ()):
                t = sample[0] if isinstance(sample, tuple) else sample.t
                if t + eps >= s.next_t:
                    out.extend(s.build(sample))
                    s.sent += 1
                    # Anchor on the sample grid with 1% slack so jitter-free samples are never skipped.
                    s.next_t = t + 0.99 * s.interval_s
        tw = self.true_wind
        if not math.isinf(tw.interval_s) and now + eps >= tw.next_t:
            out.extend(tw.build())
            tw.next_t = max(tw.next_t + tw.interval_s, now)
        return out
