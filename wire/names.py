"""Names on the wire between the mission process and the SITL's recorder (one place, both sides).

A mission (any MAVLink client) tells the world what it is doing with two standard messages, so
a ground station, a log and ``windseek sitl --rrd`` all see it:

- strategy state and mode changes: STATUSTEXT, severity INFO, text ``"<STATE_PREFIX>name"``
  (e.g. ``"state: surge"``); any other STATUSTEXT from a non-autopilot component is logged too;
- the declared source: NAMED_VALUE_FLOAT ``SRC_N``, ``SRC_E``, ``SRC_D`` (m, NED, the
  autopilot's local frame) and then ``SRC_CONF`` (confidence 0..1), sent together, in that
  order; ``SRC_CONF`` completes a declaration.

:func:`declaration_messages` and :func:`statustext_message` build them with pymavlink;
:func:`declaration_fields` gives the MAVSDK ``mavlink_direct`` (message name, JSON fields) pairs.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from wire.dialect import mavlink as mav

STATE_PREFIX = "state: "
SRC_NAMES = ("SRC_N", "SRC_E", "SRC_D")
SRC_CONF = "SRC_CONF"
#: The mission's component id: MAV_COMP_ID_MISSIONPLANNER.
MISSION_COMPONENT = 190
#: The external wind estimator's component id: MAV_COMP_ID_ONBOARD_COMPUTER.
ESTIMATOR_COMPONENT = 191


def declaration_messages(t_s: float, declared_ned: Sequence[float], confidence: float) -> list[object]:
    """NAMED_VALUE_FLOAT SRC_N/E/D/CONF for a declaration at vehicle time ``t_s`` [s]."""
    ms = int(round(t_s * 1e3)) & 0xFFFFFFFF
    vals = [*(float(v) for v in declared_ned[:3]), float(confidence)]
    names = (*SRC_NAMES, SRC_CONF)
    return [mav.MAVLink_named_value_float_message(ms, n.encode(), v) for n, v in zip(names, vals, strict=True)]


def statustext_message(text: str, severity: int = mav.MAV_SEVERITY_INFO) -> object:
    """One STATUSTEXT (truncated to the 50 characters MAVLink allows)."""
    return mav.MAVLink_statustext_message(severity, text.encode()[:50])


def declaration_fields(t_s: float, declared_ned: Sequence[float], confidence: float) -> list[tuple[str, str]]:
    """The declaration as MAVSDK ``mavlink_direct`` (message_name, fields_json) pairs."""
    ms = int(round(t_s * 1e3)) & 0xFFFFFFFF
    vals = [*(float(v) for v in declared_ned[:3]), float(confidence)]
    return [("NAMED_VALUE_FLOAT", json.dumps({"time_boot_ms": ms, "name": n, "value": v}))
            for n, v in zip((*SRC_NAMES, SRC_CONF), vals, strict=True)]  # fmt: skip


def state_fields(state: str) -> tuple[str, str]:
    """A strategy state change as a MAVSDK ``mavlink_direct`` STATUSTEXT (message_name, fields_json)."""
    text = (STATE_PREFIX + state)[:50]
    return "STATUSTEXT", json.dumps({"severity": int(mav.MAV_SEVERITY_INFO), "text": text, "id": 0, "chunk_seq": 0})


async def publish(direct: Any, pairs: list[tuple[str, str]]) -> None:
    """Send (message_name, fields_json) pairs through a MAVSDK ``MavlinkDirectAsync`` plugin, e.g.
    ``await publish(direct, [state_fields("surge")])`` on a state change and
    ``await publish(direct, declaration_fields(t, ned, conf))`` once at the declaration."""
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    for name, fields in pairs:
        await direct.send_message(MavlinkMessage(message_name=name, fields_json=fields))


__all__ = ["publish", "ESTIMATOR_COMPONENT", "MISSION_COMPONENT", "SRC_CONF", "SRC_NAMES", "STATE_PREFIX",
           "declaration_fields", "declaration_messages", "state_fields", "statustext_message"]  # fmt: skip
