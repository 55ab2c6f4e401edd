"""COMMAND_LONG and COMMAND_INT: every command is answered with one COMMAND_ACK.

Supported: COMPONENT_ARM_DISARM (pre-arm checks, 21196 forces a disarm in the air),
NAV_TAKEOFF (param7 AMSL altitude as on PX4, NaN = MIS_TAKEOFF_ALT), NAV_LAND, NAV_RETURN_TO_LAUNCH,
DO_SET_MODE (PX4 custom main/sub modes), MISSION_START, DO_SET_MISSION_CURRENT, DO_LAND_START,
DO_REPOSITION, DO_CHANGE_SPEED,
SET_MESSAGE_INTERVAL, GET_MESSAGE_INTERVAL, REQUEST_MESSAGE (streamed messages, AUTOPILOT_VERSION),
REQUEST_AUTOPILOT_CAPABILITIES.
Anything else: MAV_RESULT_UNSUPPORTED. A supported command with bad parameters: DENIED; a
command the vehicle cannot do in its state: TEMPORARILY_REJECTED or DENIED, as PX4 does. Every
refusal also says why in a STATUSTEXT (PX4's ``mavlink_log_critical``), so a ground station
that only shows the ACK's result code still tells its user the reason; except a refused message
request (REQUEST_MESSAGE, SET/GET_MESSAGE_INTERVAL), which ground stations send as probes.

NAV_TAKEOFF follows PX4's navigator (``takeoff.cpp``): param7 is the target altitude **AMSL**.
A target below the vehicle's altitude (MAVProxy's ``takeoff 5`` and dronekit's
``simple_takeoff(5)`` send 5 m AMSL, far below a home at 488 m) is accepted with the critical
STATUSTEXT "Already higher than takeoff altitude" and the vehicle does not climb (PX4 takes off
to its current altitude and switches to Hold); windseek adds an INFO line with the AMSL home
altitude so the user sees what to send.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

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
CANCELLED = 6  # MAV_RESULT_CANCELLED (not in pymavlink 2.4.50's common.xml): PX4's answer to DO_LAND_START
MAV_CMD_DO_LAND_START = 189

FORCE_MAGIC = 21196

CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE  # INT32 parameters travel bytewise, as on PX4
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mav.MAV_PROTOCOL_CAPABILITY_FTP
)
#: Reported flight software version: 1.15.0 release, like PX4's (major, minor, patch, type 255).
FLIGHT_SW_VERSION = (1 << 24) | (15 << 16) | (0 << 8) | 255


def autopilot_version() -> object:
    """AUTOPILOT_VERSION: PX4's capability bits (as far as this SITL has them), version 1.15.0 official."""
    return mav.MAVLink_autopilot_version_message(
        CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, b"\0" * 8, b"\0" * 8, b"\0" * 8, 0x26AC, 0x11,
        0x5749_4E44_5345_454B, [0] * 18,
    )  # fmt: skip


class CommandHandler:
    """Executes commands against the built-in autopilot (:class:`AutopilotPort`)."""

    def __init__(self, ep: Endpoint, ap: AutopilotPort, streams: StreamScheduler) -> None:
        self.ep = ep
        self.ap = ap
        self.streams = streams
        self._after_ack: list = []
        self._why = ""
        #: Index of the uploaded mission's DO_LAND_START item (None: none), set by the mission protocol.
        self.land_start_index: Callable[[], int | None] = lambda: None
        ep.handlers["COMMAND_LONG"] = self.on_command_long
        ep.handlers["COMMAND_INT"] = self.on_command_int

    # ------------------------------------------------------------------ entry points
    def on_command_long(self, msg: Any, link: Link) -> None:
        if not targets_us(msg):
            return
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        latlon = None
        if msg.command == mav.MAV_CMD_DO_REPOSITION:
            latlon = (p[4], p[5])
        self._run(msg, link, p, latlon, mav.MAV_FRAME_GLOBAL)

    def on_command_int(self, msg: Any, link: Link) -> None:
        if not targets_us(msg):
            return
        p = [msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z]
        latlon = (msg.x * 1e-7, msg.y * 1e-7) if (msg.x or msg.y) else (math.nan, math.nan)
        self._run(msg, link, p, latlon, msg.frame)

    def _run(self, msg: Any, link: Link, p: list[float], latlon: tuple | None, frame: int) -> None:
        cmd = int(msg.command)
        self._why = ""
        try:
            result = self.execute(cmd, p, latlon, frame, link)
        except Exception:
            log.warning("command %d failed", cmd, exc_info=True)
            self.ep.counters["handler_errors"] += 1
            result = FAILED
        if result is None:
            return
        self.ep.reply(
            mav.MAVLink_command_ack_message(cmd, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), link
        )
        # Requested messages follow their COMMAND_ACK, as on PX4.
        after, self._after_ack = self._after_ack, []
        if result == ACCEPTED:
            self.ep.reply_many(after, link)
            if cmd in MODE_COMMANDS:
                self.ap.mode_commanded()
            return
        self.ep.counters["commands_refused"] += 1
        if result != UNSUPPORTED and cmd not in PROBE_COMMANDS:
            # Say why, as PX4 does with mavlink_log_critical (the ACK alone carries only a code).
            name = mav.enums["MAV_CMD"][cmd].name.removeprefix("MAV_CMD_") if cmd in mav.enums["MAV_CMD"] else str(cmd)
            why = self._why or _RESULT_NAMES.get(result, "refused")
            text = f"{name}: {why}"
            self.ap.fc.say((text if len(text) <= 50 else why)[:50], 2)  # STATUSTEXT holds 50 characters

    def _ok(self, result: tuple[bool, str]) -> int:
        """ACCEPTED, or DENIED with the autopilot's reason kept for the STATUSTEXT."""
        ok, why = result
        if not ok:
            self._why = why
        return ACCEPTED if ok else DENIED

    def _deny(self, why: str, result: int = DENIED) -> int:
        self._why = why
        return result

    # ------------------------------------------------------------------ commands
    def execute(self, cmd: int, p: list[float], latlon: tuple | None, frame: int, link: Link) -> int | None:
        """Run one command; returns the MAV_RESULT (None: the command acknowledges itself)."""
        fc = self.ap.fc
        if cmd == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0:
                return self._ok(fc.arm())
            if p[0] == 0.0:
                return self._ok(fc.disarm(force=p[1] == FORCE_MAGIC))  # param2 may be NaN (MAVSDK)
            return self._deny(f"param1 {p[0]:g}: 1 arms, 0 disarms")
        if cmd == mav.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff(p[6])
        if cmd == mav.MAV_CMD_NAV_LAND:
            return self._ok(fc.land())
        if cmd == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._ok(fc.rtl())
        if cmd == mav.MAV_CMD_DO_SET_MODE:
            return self._set_mode(p)
        if cmd == mav.MAV_CMD_MISSION_START:
            first = int(p[0]) if math.isfinite(p[0]) and p[0] > 0 else None
            return self._ok(fc.start_mission(first))
        if cmd == MAV_CMD_DO_LAND_START:
            # PX4's navigator: continue the mission from its DO_LAND_START item, else CANCELLED.
            i = self.land_start_index()
            if i is None:
                return self._deny("planned mission landing not available", CANCELLED)
            return self._ok(fc.start_mission(i))
        if cmd == mav.MAV_CMD_DO_SET_MISSION_CURRENT:
            fc_n = len(fc.mission)
            if not (math.isfinite(p[0]) and 0 <= p[0] < fc_n):
                return self._deny(f"mission item {p[0]:g} not in [0, {fc_n - 1}]")
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
            return self._ok(fc.set_speed(p[1]))
        if cmd in (mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_GET_MESSAGE_INTERVAL, mav.MAV_CMD_REQUEST_MESSAGE):
            if not math.isfinite(p[0]):
                return self._deny("message id must be finite")
            msg_id = int(p[0])
            if cmd == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
                ok = self.streams.set_interval(msg_id, p[1], self.ap.clock())
                return ACCEPTED if ok else self._deny(f"message {msg_id} is not streamed")
            if cmd == mav.MAV_CMD_GET_MESSAGE_INTERVAL:
                us = self.streams.interval_us(msg_id)
                if us is None:
                    return self._deny(f"message {msg_id} is not streamed")
                self._after_ack.append(mav.MAVLink_message_interval_message(msg_id, us))
                return ACCEPTED
            return ACCEPTED if self.send_requested(msg_id, link, p) else self._deny(f"message {msg_id} not available")
        if cmd == mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self.send_requested(mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, link, p)
            return ACCEPTED
        return UNSUPPORTED

    def _takeoff(self, alt_amsl: float) -> int:
        """NAV_TAKEOFF as PX4's navigator treats param7 (AMSL; NaN: MIS_TAKEOFF_ALT above home)."""
        fc = self.ap.fc
        if not fc.armed:
            return self._deny("not armed")
        if not math.isfinite(alt_amsl):
            fc.say(f"Using default takeoff altitude: {fc.config.takeoff_altitude_m:.1f} m")
            return self._ok(fc.takeoff(None))
        home = self.ap.home_amsl()
        now_amsl = self.ap.home.alt_m - float(self.ap.position()[2])
        if alt_amsl < now_amsl:
            # PX4 takes off to the current altitude instead (no climb) and holds.
            fc.say("Already higher than takeoff altitude", 2)
            fc.say(f"Takeoff altitude is AMSL: home is {home:.1f} m", 6)
            fc.hold()
            return ACCEPTED
        return self._ok(fc.takeoff(alt_amsl - home))

    def _set_mode(self, p: list[float]) -> int:
        fc = self.ap.fc
        if not (math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(p[2])):
            return self._deny("mode parameters must be finite")
        if not int(p[0]) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return self._deny("only PX4 custom modes are supported")
        mode = mode_from_px4(int(p[1]), int(p[2]))
        if mode is None:
            return self._deny(f"mode {int(p[1])}/{int(p[2])} not supported")
        if mode == Mode.OFFBOARD and not fc.offboard_active(self.ap.clock()):
            return self._deny("no offboard setpoint stream", REJECTED)
        return self._ok(fc.set_mode(mode))

    def _reposition(self, p: list[float], latlon: tuple | None, frame: int) -> int:
        home = self.ap.home
        lat, lon = latlon if latlon is not None else (math.nan, math.nan)
        alt = p[6]
        if not all(math.isnan(v) or math.isfinite(v) for v in (lat, lon, alt)):
            return self._deny("position must be finite or NaN")
        if math.isfinite(lat) and not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return self._deny("latitude/longitude out of range")
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
            return self._deny("target more than 100 km away")
        yaw = math.radians(p[3]) if math.isfinite(p[3]) else math.nan
        if math.isfinite(p[0]) and p[0] > 0:
            self.ap.fc.set_speed(p[0])
        return self._ok(self.ap.fc.reposition(target, yaw))

    def send_requested(self, msg_id: int, link: Link, p: list[float]) -> bool:
        """Send one requested message on ``link``; False if it is not something we have."""
        if msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self._after_ack.append(autopilot_version())
            return True
        msgs = self.streams.build_once(msg_id)
        if not msgs:
            return False
        self._after_ack.extend(msgs)
        return True


#: Commands whose acceptance is a mode choice (ends a mission's landing as reported by the telemetry).
MODE_COMMANDS = {mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH,
                 mav.MAV_CMD_DO_SET_MODE,
                 mav.MAV_CMD_MISSION_START, MAV_CMD_DO_LAND_START, mav.MAV_CMD_DO_REPOSITION,
                 mav.MAV_CMD_COMPONENT_ARM_DISARM}  # fmt: skip
#: Requests a ground station sends to probe what the vehicle has (QGC asks for COMPONENT_METADATA,
#: AVAILABLE_MODES ... at every connection): refused by the ACK code alone, as PX4 does, not on the console.
PROBE_COMMANDS = {mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_GET_MESSAGE_INTERVAL}
_RESULT_NAMES = {DENIED: "denied", REJECTED: "temporarily rejected", FAILED: "failed", CANCELLED: "cancelled"}
