"""COMMAND_LONG and COMMAND_INT: every command is answered with one COMMAND_ACK.

Supported: COMPONENT_ARM_DISARM (pre-arm checks, 21196 forces a disarm in the air),
NAV_TAKEOFF (param7 AMSL altitude, NaN = MIS_TAKEOFF_ALT), NAV_LAND, NAV_RETURN_TO_LAUNCH,
DO_SET_MODE (PX4 custom main/sub modes), MISSION_START, DO_SET_MISSION_CURRENT, DO_REPOSITION,
DO_CHANGE_SPEED,
SET_MESSAGE_INTERVAL, GET_MESSAGE_INTERVAL, REQUEST_MESSAGE, REQUEST_AUTOPILOT_CAPABILITIES.
Anything else: MAV_RESULT_UNSUPPORTED. A supported command with bad parameters: DENIED; a
command the vehicle cannot do in its state: TEMPORARILY_REJECTED or DENIED, as PX4 does.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from sitl.autopilot.flight_modes import Mode
from sitl.link.endpoint import Endpoint, Link, targets_us
from sitl.link.port import AutopilotPort
from sitl.link.telemetry import mode_from_px4
from sitl.world.sensors import geodetic_to_ned
from wire.dialect import mavlink as mav

if TYPE_CHECKING:
    from sitl.link.streams import StreamScheduler

log = logging.getLogger(__name__)

ACCEPTED = mav.MAV_RESULT_ACCEPTED
DENIED = mav.MAV_RESULT_DENIED
UNSUPPORTED = mav.MAV_RESULT_UNSUPPORTED
REJECTED = mav.MAV_RESULT_TEMPORARILY_REJECTED
FAILED = mav.MAV_RESULT_FAILED

FORCE_MAGIC = 21196

CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
)
#: Reported flight software version: 1.15.0 release, like PX4's (major, minor, patch, type 255).
FLIGHT_SW_VERSION = (1 << 24) | (15 << 16) | (0 << 8) | 255


class CommandHandler:
    """Executes commands against the built-in autopilot (:class:`AutopilotPort`)."""

    def __init__(self, ep: Endpoint, ap: AutopilotPort, streams: StreamScheduler) -> None:
        self.ep = ep
        self.ap = ap
        self.streams = streams
        self._after_ack: list = []
        ep.handlers["COMMAND_LONG"] = self.on_command_long
        ep.handlers["COMMAND_INT"] = self.on_command_int

    # ------------------------------------------------------------------ entry points
    def on_command_long(self, msg: object, link: Link) -> None:
        if not targets_us(msg):
            return
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        latlon = None
        if msg.command == mav.MAV_CMD_DO_REPOSITION:
            latlon = (p[4], p[5])
        self._run(msg, link, p, latlon, mav.MAV_FRAME_GLOBAL)

    def on_command_int(self, msg: object, link: Link) -> None:
        if not targets_us(msg):
            return
        p = [msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z]
        latlon = (msg.x * 1e-7, msg.y * 1e-7) if (msg.x or msg.y) else (math.nan, math.nan)
        self._run(msg, link, p, latlon, msg.frame)

    def _run(self, msg: object, link: Link, p: list[float], latlon: tuple | None, frame: int) -> None:
        cmd = int(msg.command)
        try:
            result = self.execute(cmd, p, latlon, frame, link)
        except Exception:
            log.warning("command %d failed", cmd, exc_info=True)
            self.ep.counters["handler_errors"] += 1
            result = FAILED
        if result is None:
            return
        self.ep.send(
            mav.MAVLink_command_ack_message(cmd, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), link
        )
        # Requested messages follow their COMMAND_ACK, as on PX4.
        after, self._after_ack = self._after_ack, []
        if result == ACCEPTED:
            self.ep.send_many(after, link)
        if result != ACCEPTED:
            self.ep.counters["commands_refused"] += 1

    # ------------------------------------------------------------------ commands
    def execute(self, cmd: int, p: list[float], latlon: tuple | None, frame: int, link: Link) -> int | None:
        """Run one command; returns the MAV_RESULT (None: the command acknowledges itself)."""
        fc = self.ap.fc
        if cmd == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0:
                ok, _ = fc.arm()
                return ACCEPTED if ok else DENIED
            if p[0] == 0.0:
                ok, _ = fc.disarm(force=p[1] == FORCE_MAGIC)  # param2 may be NaN (MAVSDK)
                return ACCEPTED if ok else DENIED
            return DENIED
        if cmd == mav.MAV_CMD_NAV_TAKEOFF:
            alt = None
            if math.isfinite(p[6]):
                alt = p[6] - self.ap.home_amsl()
            ok, _ = fc.takeoff(alt)
            return ACCEPTED if ok else DENIED
        if cmd == mav.MAV_CMD_NAV_LAND:
            ok, _ = fc.land()
            return ACCEPTED if ok else DENIED
        if cmd == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            ok, _ = fc.rtl()
            return ACCEPTED if ok else DENIED
        if cmd == mav.MAV_CMD_DO_SET_MODE:
            return self._set_mode(p)
        if cmd == mav.MAV_CMD_MISSION_START:
            first = int(p[0]) if math.isfinite(p[0]) and p[0] > 0 else None
            ok, _ = fc.start_mission(first)
            return ACCEPTED if ok else DENIED
        if cmd == mav.MAV_CMD_DO_SET_MISSION_CURRENT:
            fc_n = len(fc.mission)
            if not (math.isfinite(p[0]) and 0 <= p[0] < fc_n):
                return DENIED
            if fc.mode == Mode.MISSION and fc.armed:
                fc.start_mission(int(p[0]))
            else:
                fc.mission_index = int(p[0])
            self.ap.mission_changed()
            return ACCEPTED
        if cmd == mav.MAV_CMD_DO_REPOSITION:
            return self._reposition(p, latlon, frame)
        if cmd == mav.MAV_CMD_DO_CHANGE_SPEED:
            if not math.isfinite(p[1]) or p[1] == -1.0:
                return ACCEPTED  # -1: no change
            ok, _ = fc.set_speed(p[1])
            return ACCEPTED if ok else DENIED
        if cmd == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            if not math.isfinite(p[0]):
                return DENIED
            return ACCEPTED if self.streams.set_interval(int(p[0]), p[1], self.ap.clock()) else DENIED
        if cmd == mav.MAV_CMD_GET_MESSAGE_INTERVAL:
            if not math.isfinite(p[0]):
                return DENIED
            us = self.streams.interval_us(int(p[0]))
            if us is None:
                return DENIED
            self._after_ack.append(mav.MAVLink_message_interval_message(int(p[0]), us))
            return ACCEPTED
        if cmd == mav.MAV_CMD_REQUEST_MESSAGE:
            if not math.isfinite(p[0]):
                return DENIED
            return ACCEPTED if self.send_requested(int(p[0]), link, p) else DENIED
        if cmd == mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self.send_requested(mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, link, p)
            return ACCEPTED
        return UNSUPPORTED

    def _set_mode(self, p: list[float]) -> int:
        fc = self.ap.fc
        if not (math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(p[2])):
            return DENIED
        if not int(p[0]) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return DENIED
        mode = mode_from_px4(int(p[1]), int(p[2]))
        if mode is None:
            return DENIED
        if mode == Mode.OFFBOARD and not fc.offboard_active(self.ap.clock()):
            return REJECTED
        ok, _ = fc.set_mode(mode)
        return ACCEPTED if ok else DENIED

    def _reposition(self, p: list[float], latlon: tuple | None, frame: int) -> int:
        home = self.ap.home
        lat, lon = latlon if latlon is not None else (math.nan, math.nan)
        alt = p[6]
        if not all(math.isnan(v) or math.isfinite(v) for v in (lat, lon, alt)):
            return DENIED
        if math.isfinite(lat) and not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return DENIED
        target = np.full(3, math.nan)
        if math.isfinite(lat) and math.isfinite(lon):
            ned = geodetic_to_ned(lat, lon, home.alt_m, home)
            target[0:2] = ned[0:2]
        if math.isfinite(alt):
            if frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
                target[2] = self.ap.fc.home[2] - alt
            else:
                target[2] = home.alt_m - alt
        if np.any(np.abs(np.nan_to_num(target)) > 1e5):
            return DENIED
        yaw = math.radians(p[3]) if math.isfinite(p[3]) else math.nan
        if math.isfinite(p[0]) and p[0] > 0:
            self.ap.fc.set_speed(p[0])
        ok, _ = self.ap.fc.reposition(target, yaw)
        return ACCEPTED if ok else DENIED

    def send_requested(self, msg_id: int, link: Link, p: list[float]) -> bool:
        """Send one requested message on ``link``; False if it is not something we have."""
        if msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self._after_ack.append(
                mav.MAVLink_autopilot_version_message(
                    CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, b"\0" * 8, b"\0" * 8, b"\0" * 8, 0x26AC, 0x11,
                    0x5749_4E44_5345_454B, [0] * 18,
                )
            )  # fmt: skip
            return True
        msgs = self.streams.build_once(msg_id)
        if not msgs:
            return False
        self._after_ack.extend(msgs)
        return True
