"""Take-off to an altitude above home that PX4 cannot mistake: MAV_CMD_NAV_TAKEOFF with the target altitude AMSL.

MAVSDK's ``Action.takeoff`` sends MAV_CMD_NAV_TAKEOFF without an altitude, so PX4's navigator uses its
``MIS_TAKEOFF_ALT`` (``src/modules/navigator/takeoff.cpp`` 182-195); MAVSDK's ``set_takeoff_altitude`` sets that
parameter first. With PX4 SIH at 4x real time the navigator was seen taking off to the default 2.5 m although
MIS_TAKEOFF_ALT read back 10 m before the arming (twice in about ten flights; not understood). The command's
param7 (AMSL altitude) is used by the navigator as is (``navigator_main.cpp`` 598-638), so this sends it with
home's altitude (HOME_POSITION, mm AMSL) plus the altitude wanted. Every wait is bounded.
"""

from __future__ import annotations

import asyncio
import json
import math
import time

from mission.runners.mavsdk_vehicle import MavsdkVehicle

MAV_CMD_NAV_TAKEOFF = 22
MAV_RESULT_ACCEPTED = 0


async def takeoff_above_home(v: MavsdkVehicle, altitude_m: float, timeout_s: float = 10.0) -> str | None:
    """Command the take-off to ``altitude_m`` above home (m); None when PX4 accepted it, else the reason."""
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    end = time.monotonic() + timeout_s
    while v.home is None and time.monotonic() < end:
        await asyncio.sleep(0.1)
    if v.home is None or v.target is None:
        return f"no HOME_POSITION within {timeout_s:g} s: the take-off altitude cannot be placed"
    amsl = float(v.home["altitude"]) * 1e-3 + float(altitude_m)
    nan = math.nan
    fields = {"target_system": v.target[0], "target_component": v.target[1], "command": MAV_CMD_NAV_TAKEOFF,
              "confirmation": 0, "param1": nan, "param2": 0.0, "param3": 0.0, "param4": nan, "param5": nan,
              "param6": nan, "param7": amsl}  # fmt: skip
    msg = MavlinkMessage(message_name="COMMAND_LONG", target_system_id=v.target[0], target_component_id=v.target[1],
                         fields_json=json.dumps(fields).replace("NaN", "null"))  # fmt: skip
    try:
        ack = await asyncio.wait_for(v.direct.send_command(msg), timeout_s)
    except TimeoutError:
        return f"take-off: no answer within {timeout_s:g} s"
    except Exception as e:  # noqa: BLE001 - MavlinkDirectError: the reason
        return f"take-off: {e}"
    result = json.loads(ack.fields_json or "{}").get("result")
    return None if result == MAV_RESULT_ACCEPTED else f"take-off refused (MAV_RESULT {result})"
