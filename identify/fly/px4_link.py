"""PX4 parameters and message rates over MAVSDK for the identification flight: a thin asyncio adapter.

- :func:`request_streams`: MAV_CMD_SET_MESSAGE_INTERVAL (511) for each wanted message, through MAVSDK's
  ``mavlink_direct.send_command`` (it retransmits and returns the final COMMAND_ACK); the result per message.
- :class:`Params`: typed reads and writes. PX4 parameters are INT32 or REAL32 and PX4 refuses a set of the
  other type, so each name is read with the type PX4 declares it with (the other is tried if that fails)
  and written back with the same type, then read back to verify.
- :func:`link_loss_failsafe`: the data-link-loss and offboard-loss failsafes set and read back (values and
  the originals, to restore after the flight).

Every call has a bound (``timeout_s`` wall seconds); failures are one-line strings, never exceptions
escaping to the flight loop.
"""

from __future__ import annotations

import asyncio
import json
import math
from dataclasses import dataclass, field
from typing import Any

#: MAV_CMD_SET_MESSAGE_INTERVAL and the message ids the identification asks for.
SET_MESSAGE_INTERVAL = 511
MESSAGE_IDS = {"HIGHRES_IMU": 105, "SCALED_IMU": 26, "ATTITUDE_QUATERNION": 31, "ATTITUDE": 30,
               "LOCAL_POSITION_NED": 32, "ACTUATOR_OUTPUT_STATUS": 375, "SERVO_OUTPUT_RAW": 36, "ESC_STATUS": 291,
               "EXTENDED_SYS_STATE": 245}  # fmt: skip
#: MAV_RESULT names of a COMMAND_ACK.
MAV_RESULT = {0: "accepted", 1: "temporarily rejected", 2: "denied", 3: "unsupported", 4: "failed", 5: "in progress",
              6: "cancelled"}  # fmt: skip


async def request_streams(direct: Any, target: tuple[int, int], wanted: dict[str, float],
                          timeout_s: float = 5.0) -> dict[str, str]:  # fmt: skip
    """SET_MESSAGE_INTERVAL for each ``name: Hz`` of ``wanted``; per name the autopilot's answer in words."""
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    out: dict[str, str] = {}
    for name, hz in wanted.items():
        fields = {"target_system": target[0], "target_component": target[1], "command": SET_MESSAGE_INTERVAL,
                  "confirmation": 0, "param1": float(MESSAGE_IDS[name]), "param2": 1e6 / hz, "param3": 0.0,
                  "param4": 0.0, "param5": 0.0, "param6": 0.0, "param7": 0.0}  # fmt: skip
        cmd = MavlinkMessage(message_name="COMMAND_LONG", target_system_id=target[0],
                             target_component_id=target[1], fields_json=json.dumps(fields))  # fmt: skip
        try:
            ack = await asyncio.wait_for(direct.send_command(cmd), timeout_s)
            res = int(json.loads(ack.fields_json or "{}").get("result", -1))
            out[name] = MAV_RESULT.get(res, "no answer")
        except TimeoutError:
            out[name] = f"no answer within {timeout_s:g} s"
        except Exception as e:  # noqa: BLE001 - MavlinkDirectError: the reason
            out[name] = f"failed ({e})"
    return out


@dataclass
class Params:
    """Typed PX4 parameter access through MAVSDK's param plugin (see the module docstring)."""

    param: Any
    timeout_s: float = 5.0
    kinds: dict[str, str] = field(default_factory=dict)

    async def get(self, name: str, kind: str = "int") -> float | None:
        """The value (None when the autopilot has no such parameter or does not answer)."""
        order = [kind, "float" if kind == "int" else "int"]
        for k in order:
            getter = self.param.get_param_int if k == "int" else self.param.get_param_float
            try:
                v = float(await asyncio.wait_for(getter(name), self.timeout_s))
            except Exception:  # noqa: BLE001 - wrong type, unknown, or a timeout: try the other type
                continue
            self.kinds[name] = k
            return v
        return None

    async def set(self, name: str, value: float) -> float:
        """Write ``value`` with the parameter's own type (learned by :meth:`get`) and read it back;
        RuntimeError with the reason when it fails or reads back otherwise."""
        if name not in self.kinds:
            await self.get(name)
        kind = self.kinds.get(name)
        if kind is None:
            raise RuntimeError(f"{name}: no such parameter on the autopilot")
        try:
            if kind == "int":
                await asyncio.wait_for(self.param.set_param_int(name, int(round(value))), self.timeout_s)
            else:
                await asyncio.wait_for(self.param.set_param_float(name, float(value)), self.timeout_s)
        except Exception as e:  # noqa: BLE001 - ParamError, a timeout
            raise RuntimeError(f"{name}: could not set {value:g} ({type(e).__name__}: {e})") from None
        back = await self.get(name, kind)
        if back is None or not math.isclose(back, float(int(round(value))) if kind == "int" else value,
                                            rel_tol=1e-5, abs_tol=1e-6):  # fmt: skip
            raise RuntimeError(f"{name}: set to {value:g} but read back {back}")
        return back


#: The failsafes of the identification flight: (parameter, PX4 type, value; the timeouts are replaced by the
#: options' wall seconds times the speed).
#: NAV_DLL_ACT 3 = land on data-link loss; COM_OBL_RC_ACT 5 = hold on offboard loss (PX4's default 0,
#: position mode, needs a pilot's sticks).
FAILSAFES = (("NAV_DLL_ACT", "int", 3.0), ("COM_DL_LOSS_T", "int", 5.0), ("COM_OBL_RC_ACT", "int", 5.0),
             ("COM_OF_LOSS_T", "float", 1.0))


async def link_loss_failsafe(params: Params, speed: float, dl_loss_s: float, of_loss_s: float
                             ) -> tuple[dict[str, float], dict[str, float], list[str]]:  # fmt: skip
    """Set the failsafes of :data:`FAILSAFES` and read them back. The loss timeouts are wall seconds times the
    simulator's ``speed`` (PX4's timers run on its clock, MAVSDK's heartbeats on the wall clock; PX4 allows
    COM_DL_LOSS_T 5-300 s and COM_OF_LOSS_T 0-60 s). A data-link-loss action already on (1 hold, 2 return,
    3 land) is kept. Returns (values now, values before, problems in words)."""
    now: dict[str, float] = {}
    before: dict[str, float] = {}
    problems: list[str] = []
    wanted = {"COM_DL_LOSS_T": min(max(round(dl_loss_s * speed), 5), 300),
              "COM_OF_LOSS_T": min(max(of_loss_s * speed, 0.1), 60.0)}  # fmt: skip
    for name, kind, value in FAILSAFES:
        old = await params.get(name, kind)
        if old is None:
            problems.append(f"{name}: not on this autopilot (or no answer)")
            continue
        before[name] = old
        target = float(wanted.get(name, value))
        if name == "NAV_DLL_ACT" and int(old) in (1, 2, 3):
            now[name] = old
            continue
        try:
            now[name] = old if math.isclose(old, target) else await params.set(name, target)
        except RuntimeError as e:
            problems.append(str(e))
    return now, before, problems
