"""What the MAVSDK runner does differently when the autopilot is ArduCopter: a thin adapter.

- **Modes.** ArduCopter's HEARTBEAT ``custom_mode`` is its mode number (``ArduCopter/mode.h``). The
  mission loop speaks PX4's mode names for what a mode *does* (:data:`mission.vehicle.VehicleState.mode`),
  so :func:`loop_mode` maps ArduCopter's: GUIDED is ``OFFBOARD`` while the runner streams setpoints
  (MAVSDK's offboard plugin switches ArduCopter to GUIDED and sends SET_POSITION_TARGET_LOCAL_NED)
  and ``AUTO.LOITER`` otherwise (a GUIDED take-off ends hovering at its target); LOITER, BRAKE and
  POSHOLD are ``AUTO.LOITER``, LAND ``AUTO.LAND``, RTL and SMART_RTL ``AUTO.RTL``, AUTO ``AUTO.MISSION``.
  The ArduCopter name is kept for the messages (:func:`copter_mode_name`).
- **Streams.** ArduPilot streams on a serial port only what was asked for there (``SRn_*``, or a
  ground station's requests): the runner asks with SET_MESSAGE_INTERVAL for what it and the
  estimator read (:data:`STREAMS`), as ``windseek estimator`` does.
- **The ground-station failsafe** (PX4's data-link loss): ``FS_GCS_ENABLE`` is made non-zero (5, land,
  when it was 0) and read back; ArduPilot follows the heartbeats of system ``MAV_GCS_SYSID`` only
  (``SYSID_MYGCS`` before ArduPilot 4.7), so the runner says whether that is its own system id.
- **Take-off**: MAV_CMD_NAV_TAKEOFF's ``param7`` is the altitude above home on ArduCopter (PX4: AMSL).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from typing import Any

#: ArduCopter's mode numbers (ArduCopter/mode.h ``Mode::Number``).
COPTER_MODES = {0: "STABILIZE", 1: "ACRO", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL", 7: "CIRCLE",
                9: "LAND", 11: "DRIFT", 13: "SPORT", 14: "FLIP", 15: "AUTOTUNE", 16: "POSHOLD", 17: "BRAKE",
                18: "THROW", 19: "AVOID_ADSB", 20: "GUIDED_NOGPS", 21: "SMART_RTL", 22: "FLOWHOLD", 23: "FOLLOW",
                24: "ZIGZAG", 25: "SYSTEMID", 26: "AUTOROTATE", 27: "AUTO_RTL", 28: "TURTLE"}  # fmt: skip
GUIDED = 4
#: ArduCopter mode -> the PX4 name of what it does for the mission loop (GUIDED: see :func:`loop_mode`).
_LOOP_NAMES = {"LOITER": "AUTO.LOITER", "BRAKE": "AUTO.LOITER", "POSHOLD": "AUTO.LOITER", "LAND": "AUTO.LAND",
               "RTL": "AUTO.RTL", "SMART_RTL": "AUTO.RTL", "AUTO_RTL": "AUTO.RTL", "AUTO": "AUTO.MISSION"}  # fmt: skip
#: MAV_AUTOPILOT_ARDUPILOTMEGA in HEARTBEAT.autopilot.
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
#: Messages and rates (Hz of ArduPilot's clock) the runner asks ArduPilot for on its link.
STREAMS = (("HEARTBEAT", 1.0), ("SYS_STATUS", 2.0), ("EXTENDED_SYS_STATE", 5.0), ("HOME_POSITION", 1.0),
           ("GLOBAL_POSITION_INT", 5.0), ("GPS_RAW_INT", 5.0), ("LOCAL_POSITION_NED", 30.0),
           ("ATTITUDE_QUATERNION", 50.0), ("HIGHRES_IMU", 100.0))  # fmt: skip
#: The ground-station failsafe's parameters, and the action the runner sets when it is off: land.
FS_PARAM, FS_LAND = "FS_GCS_ENABLE", 5
GCS_SYSID_PARAMS = ("MAV_GCS_SYSID", "SYSID_MYGCS")


def copter_mode_name(custom_mode: int) -> str:
    """ArduCopter's name of a mode number (``MODE<n>`` when unknown)."""
    return COPTER_MODES.get(int(custom_mode), f"MODE{int(custom_mode)}")


def loop_mode(custom_mode: int, offboard: bool) -> str:
    """The mission loop's (PX4) name for what ArduCopter's mode ``custom_mode`` does; ``offboard``: the
    runner is streaming setpoints (GUIDED is then offboard control, else a hover at its target)."""
    name = copter_mode_name(custom_mode)
    if int(custom_mode) == GUIDED:
        return "OFFBOARD" if offboard else "AUTO.LOITER"
    return _LOOP_NAMES.get(name, name)


async def request_streams(v: Any, timeout_s: float = 3.0) -> None:
    """SET_MESSAGE_INTERVAL for :data:`STREAMS` on the runner's link (``v``: a MavsdkVehicle); a refusal
    or no answer is said once, and the runner goes on (its waits then say what is missing)."""
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    from wire.dialect import mavlink

    assert v.target is not None
    refused = []
    for name, hz in STREAMS:
        msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
        fields = {"target_system": v.target[0], "target_component": v.target[1],
                  "command": mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, "confirmation": 0, "param1": float(msg_id),
                  "param2": 1e6 / hz, "param3": 0.0, "param4": 0.0, "param5": 0.0, "param6": 0.0, "param7": 0.0}
        msg = MavlinkMessage(message_name="COMMAND_LONG", target_system_id=v.target[0],
                             target_component_id=v.target[1], fields_json=json.dumps(fields))  # fmt: skip
        try:
            ack = await asyncio.wait_for(v.direct.send_command(msg), timeout_s)
            result = json.loads(ack.fields_json or "{}").get("result")
        except Exception as e:  # noqa: BLE001 - MavlinkDirectError, a timeout: said below
            result = str(e) or type(e).__name__
        if result != 0:
            refused.append(f"{name} ({result})")
    asked = ", ".join(f"{n} {hz:g} Hz" for n, hz in STREAMS)
    v.say(f"mission: ArduPilot: asked for {asked}" + (f"; refused or unanswered: {', '.join(refused)}" if refused
                                                        else ""))  # fmt: skip


async def ensure_gcs_failsafe(v: Any, say: Callable[[str], None], our_sysid: int) -> None:
    """``FS_GCS_ENABLE`` on (5, land, when it was 0), read back; and whose heartbeats it follows."""
    param, timeout = v.param, v.cfg.command_timeout_s
    try:
        value = int(await asyncio.wait_for(param.get_param_int(FS_PARAM), timeout))
    except Exception as e:  # noqa: BLE001 - ParamError, a timeout
        say(f"SAFETY: could not read {FS_PARAM} ({e}): a link loss is left to ArduPilot's settings")
        return
    if value == 0:
        try:
            await asyncio.wait_for(param.set_param_int(FS_PARAM, FS_LAND), timeout)
            value = int(await asyncio.wait_for(param.get_param_int(FS_PARAM), timeout))
        except Exception as e:  # noqa: BLE001
            say(f"SAFETY: could not enable {FS_PARAM} ({e}): a link loss is left to ArduPilot's settings")
            return
        if value != FS_LAND:
            say(f"SAFETY: {FS_PARAM} read back as {value} after setting {FS_LAND}")
            return
        say(f"{FS_PARAM} was 0 (disabled): set to {FS_LAND} (land on ground-station loss), read back")
    else:
        say(f"{FS_PARAM} = {value}: ArduPilot's ground-station failsafe is on")
    for name in GCS_SYSID_PARAMS:
        try:
            gcs = int(await asyncio.wait_for(param.get_param_int(name), timeout))
        except Exception:  # noqa: BLE001 - the other name on this ArduPilot version
            continue
        if gcs != our_sysid:
            say(f"SAFETY: ArduPilot's ground-station failsafe follows system {gcs}'s heartbeats ({name}), not this "
                f"runner's {our_sysid}: a loss of this link alone is not an ArduPilot failsafe (set {name} "
                f"{our_sysid} to make it one)")  # fmt: skip
        else:
            say(f"{name} = {gcs}: ArduPilot's ground-station failsafe follows this runner's heartbeats")
        return
