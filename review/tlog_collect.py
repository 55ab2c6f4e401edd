"""Second pass over a ``.tlog``: decode the vehicle's messages the review uses into plain rows.

Only the message types in :data:`FIELDS` (and HEARTBEAT, STATUSTEXT, NAMED_VALUE_FLOAT) are decoded
with pymavlink (CRC-checked); every other frame was only counted by the survey. Rows are tuples
``(t, field values...)`` per message type, turned into columns by :mod:`review.tlog_columns`.

Which messages: the vehicle is the system and component of the first autopilot HEARTBEAT. Other
systems (a ground station's own heartbeats, a MAVSDK mission's setpoints and PINGs) are ignored; of
the vehicle's other components (``windseek estimator``, component 191, or a companion computer) only
WIND_COV and STATUSTEXT are kept, so their HEARTBEATs never count as the autopilot's arming state.

Time: a message's own time stamp (time_usec or time_boot_ms: the autopilot's boot clock); messages
without one (RAW_RPM, ESC_TELEMETRY_1_TO_4, HEARTBEAT, EXTENDED_SYS_STATE, STATUSTEXT) take the
latest boot time seen in the autopilot's own messages. The logging wall-clock time is not used (at
``windseek sitl --speed 4`` it runs 4x slower than the boot clock). Time stamps on a UNIX or GPS
epoch (ArduPilot's GPS_RAW_INT) are replaced by the latest boot time. PING's time_usec is the
requester's clock echoed (a MAVSDK client sends its host's monotonic time), never the boot clock.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from pymavlink import mavutil

from review.flight import MAX_BOOT_TIME_S
from review.tlog_scan import RecordScanner, frame_header
from wire import px4_modes

#: Message type -> the fields kept (in this order, after the time).
FIELDS: dict[str, tuple[str, ...]] = {
    "HIL_SENSOR": ("xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro"),
    "HIGHRES_IMU": ("xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro"),
    "SCALED_IMU": ("xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro"),
    "SCALED_IMU2": ("xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro"),
    "SCALED_IMU3": ("xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro"),
    "RAW_IMU": ("xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro"),
    "ATTITUDE_QUATERNION": ("q1", "q2", "q3", "q4"),
    "ATTITUDE": ("roll", "pitch", "yaw"),
    "LOCAL_POSITION_NED": ("x", "y", "z", "vx", "vy", "vz"),
    "GLOBAL_POSITION_INT": ("lat", "lon", "relative_alt", "vx", "vy", "vz"),
    "GPS_RAW_INT": ("fix_type", "lat", "lon", "alt", "vel", "cog", "satellites_visible"),
    "SYS_STATUS": ("voltage_battery", "current_battery", "battery_remaining"),
    "ESC_STATUS": ("index", "rpm"),
    "ESC_INFO": ("index", "failure_flags"),
    "ESC_TELEMETRY_1_TO_4": ("rpm",),
    "RAW_RPM": ("index", "frequency"),
    "SERVO_OUTPUT_RAW": ("port", "servo1_raw", "servo2_raw", "servo3_raw", "servo4_raw"),
    "ACTUATOR_OUTPUT_STATUS": ("actuator",),
    "WIND_COV": ("wind_x", "wind_y", "wind_z"),
    "WIND": ("direction", "speed", "speed_z"),
    "EXTENDED_SYS_STATE": ("landed_state",),
    "NAMED_VALUE_FLOAT": ("name", "value", "time_boot_ms"),
    "AUTOPILOT_VERSION": ("flight_sw_version",),
}
#: Messages whose time field is not the sender's boot clock.
FOREIGN_TIME_TYPES = frozenset({"PING"})
#: What other components of the vehicle's system may contribute.
OTHER_COMPONENT_TYPES = frozenset({"WIND_COV", "STATUSTEXT"})
#: MAVLink severities -> Rerun text levels.
SEVERITY_LEVEL = {0: "CRITICAL", 1: "CRITICAL", 2: "CRITICAL", 3: "ERROR", 4: "WARN", 5: "INFO", 6: "INFO", 7: "DEBUG"}
ARMED_FLAG = 128  # MAV_MODE_FLAG_SAFETY_ARMED
NO_AUTOPILOT, GCS_TYPE, PX4_AUTOPILOT = 8, 6, 12  # MAV_AUTOPILOT_INVALID, MAV_TYPE_GCS, MAV_AUTOPILOT_PX4


@dataclass
class Collected:
    """What the second pass found: rows per message type, arming, texts, and counts of problems."""

    rows: dict[str, list[tuple[Any, ...]]] = field(default_factory=lambda: defaultdict(list))
    armed: list[tuple[float, bool]] = field(default_factory=list)  # (t, armed) per autopilot HEARTBEAT
    texts: list[tuple[float, str, str]] = field(default_factory=list)
    wind_components: set[int] = field(default_factory=set)
    bad: Counter[str] = field(default_factory=Counter)
    off_clock: int = 0


def _msg_time(msg: Any, mtype: str, t_last: float) -> tuple[float, bool | None]:
    """(time [s], own?) of a message: its boot-clock stamp (True), else the latest boot time seen
    (False: no stamp of its own; None: a stamp off the boot clock)."""
    if mtype in FOREIGN_TIME_TYPES:
        return t_last, False
    if hasattr(msg, "time_usec"):
        t = msg.time_usec * 1e-6
    elif hasattr(msg, "time_boot_ms"):
        t = msg.time_boot_ms * 1e-3
    else:
        return t_last, False
    if not (0.0 <= t < MAX_BOOT_TIME_S):
        return t_last, None
    return t, True


class _Heartbeats:
    """Arming and mode changes of the autopilot's HEARTBEATs (PX4 mode names by ``wire.px4_modes``,
    as PX4 and QGroundControl spell them; other autopilots' by pymavlink)."""

    def __init__(self, col: Collected) -> None:
        self.col = col
        self.last_key: tuple[int, int] | None = None
        self.last_armed: bool | None = None
        self._last_mode = ""

    def add(self, t: float, m: Any) -> None:
        if m.autopilot == NO_AUTOPILOT or m.type == GCS_TYPE:  # a ground station's, when there is no vehicle
            return
        armed = bool(m.base_mode & ARMED_FLAG)
        self.col.armed.append((t, armed))
        if armed != self.last_armed:
            self.col.texts.append((t, "armed" if armed else "disarmed", "INFO"))
            self.last_armed = armed
        key = (int(m.base_mode) & ~ARMED_FLAG, int(m.custom_mode))
        if key != self.last_key:
            px4 = m.autopilot == PX4_AUTOPILOT and m.base_mode & px4_modes.CUSTOM_MODE_ENABLED
            mode = px4_modes.name(int(m.custom_mode)) if px4 else mavutil.mode_string_v10(m)
            if self.last_key is None or mode != self._last_mode:
                self.col.texts.append((t, f"mode {mode}", "INFO"))
            self._last_mode = mode
            self.last_key = key


def collect(path: Path, dialect: ModuleType, vehicle: tuple[int, int] | None, wanted: set[str],
            progress: Callable[[int], None] | None = None) -> Collected:  # fmt: skip
    """Decode the ``wanted`` message types of the vehicle (``None``: of every system) into rows."""
    mav = dialect.MAVLink(None)
    mav.robust_parsing = True
    ids = {mid for mid, cls in dialect.mavlink_map.items() if cls.msgname in wanted | {"HEARTBEAT", "STATUSTEXT"}}
    col = Collected()
    hb = _Heartbeats(col)
    sysid, ap_comp = (None, None) if vehicle is None else vehicle
    t_last = 0.0
    for _, frame in RecordScanner(path, progress=progress):
        mid, s, c = frame_header(frame)
        if mid not in ids or (sysid is not None and s != sysid):
            continue
        try:
            m = mav.decode(bytearray(frame))
        except Exception:  # bad CRC or length: counted, never fatal
            col.bad["bad CRC or length"] += 1
            continue
        mtype = m.get_type()
        other = ap_comp is not None and c != ap_comp
        if other and mtype not in OTHER_COMPONENT_TYPES:
            continue
        t, own = _msg_time(m, mtype, t_last)
        if own is None:
            col.off_clock += 1
            t = t_last
        elif own and not other:
            t_last = max(t_last, t)  # only the autopilot's stamps move its clock
        if mtype == "HEARTBEAT":
            hb.add(t, m)
        elif mtype == "STATUSTEXT":
            who = f"[{c}] " if other else ""
            col.texts.append((t, who + str(m.text), SEVERITY_LEVEL.get(m.severity, "INFO")))
        elif mtype in wanted:
            if mtype == "WIND_COV":
                col.wind_components.add(c)
            col.rows[mtype].append((t, *(getattr(m, f) for f in FIELDS[mtype])))
    return col


__all__ = ["FIELDS", "OTHER_COMPONENT_TYPES", "Collected", "collect"]
