"""Read a MAVLink telemetry log (``.tlog``) into :class:`~review.flight.FlightData`, in two streaming passes.

1. :func:`review.tlog_scan.survey`: count frames per (system, component, message id), find the
   vehicle (the first autopilot HEARTBEAT) and its autopilot.
2. :func:`review.tlog_collect.collect`: decode only the vehicle's messages the review uses, with the
   autopilot's dialect: ArduPilot's ``ardupilotmega`` (WIND, ESC_TELEMETRY_1_TO_4, AHRS2, SIMSTATE,
   ...) when HEARTBEAT.autopilot is MAV_AUTOPILOT_ARDUPILOTMEGA, else the project dialect
   (``wire.dialect``: common.xml + ESC_INFO/ESC_STATUS). Frames are CRC-checked; bad ones and
   message ids the dialect does not know are counted in the notes, never fatal.

One source per input group is chosen from the whole log (:func:`review.tlog_columns.choose_sources`):
IMU = the most frequent of HIL_SENSOR / HIGHRES_IMU / SCALED_IMU / RAW_IMU (ArduPilot only) /
SCALED_IMU2 / SCALED_IMU3; attitude = ATTITUDE_QUATERNION, else ATTITUDE; velocity and position =
LOCAL_POSITION_NED, else GLOBAL_POSITION_INT, else GPS_RAW_INT; rotor speeds = ESC_STATUS, else
ESC_TELEMETRY_1_TO_4, else RAW_RPM; without them, rotor speeds implied by SERVO_OUTPUT_RAW (servos 1-4)
or ACTUATOR_OUTPUT_STATUS (actuators 0-3), PWM 1000-2000 us -> 0..w_max (the project SITL's mapping,
an assumption for other vehicles). The in-air state comes from EXTENDED_SYS_STATE's landed state,
else from HEARTBEAT arming, else the vehicle counts as never airborne.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

from pymavlink.dialects.v20 import ardupilotmega

from review import tlog_columns as tc
from review.flight import FlightData
from review.tlog_collect import FIELDS, OTHER_COMPONENT_TYPES, Collected, collect
from review.tlog_scan import Survey, survey
from review.vehicle_info import mav_type_name, sw_version
from wire.dialect import mavlink

#: Motor orders (ESC / output number -> rotor index): the project SITL's, PX4/ArduPilot quad-X (1 FR, 2 RL, 3 FL, 4 RR).
MOTOR_ORDERS: dict[str, tuple[int, ...]] = {"windseek": (0, 1, 2, 3), "quad-x": (0, 2, 3, 1)}
FAMILIES = {mavlink.MAV_AUTOPILOT_PX4: "PX4", mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA: "ArduPilot"}


def motor_order_of(motor_order: str, simulated: bool) -> tuple[str, tuple[int, ...]]:
    """Resolve ``auto`` (the project's order for logs with simulation truth, else quad-X)."""
    if motor_order == "auto":
        motor_order = "windseek" if simulated else "quad-x"
    if motor_order not in MOTOR_ORDERS:
        raise ValueError(f"motor_order = {motor_order!r}: allowed values are auto, {', '.join(MOTOR_ORDERS)}")
    return motor_order, MOTOR_ORDERS[motor_order]


def _vehicle_counts(fd: FlightData, sv: Survey, dialect: ModuleType) -> None:
    """Frame counts of the vehicle's messages by name into ``fd.counts`` (its autopilot component's, and
    WIND_COV / STATUSTEXT of its other components); notes on what is left out."""
    keep_other = {mid for mid, cls in dialect.mavlink_map.items() if cls.msgname in OTHER_COMPONENT_TYPES}
    ids: Counter[int] = Counter()
    if sv.vehicle is None:
        fd.notes.append("no autopilot HEARTBEAT: messages of every system used")
        ids = sv.msg_counts(None)
    else:
        sysid, comp = sv.vehicle
        for (s, c, mid), n in sv.counts.items():
            if s == sysid and (c == comp or mid in keep_other):
                ids[mid] += n
        others = sv.frames - sum(sv.msg_counts(sysid).values())
        if others:
            fd.notes.append(f"{others} message(s) of systems other than the vehicle ({sysid}) ignored")
        other_comp = sum(sv.msg_counts(sysid).values()) - sum(ids.values())
        if other_comp:
            fd.notes.append(f"{other_comp} message(s) of components other than the autopilot ({sysid}:{comp}) "
                            f"ignored")  # fmt: skip
    unknown: Counter[int] = Counter()
    for mid, n in ids.items():
        cls = dialect.mavlink_map.get(mid)
        if cls is None:
            unknown[mid] += n
        else:
            fd.counts[cls.msgname] += n
    for mid, n in sorted(unknown.items()):
        fd.notes.append(f"{n} frame(s) skipped: unknown message id {mid}")


def _autopilot(fd: FlightData, sv: Survey, col: Collected, simulated: bool) -> None:
    fd.family = "windseek SITL" if simulated else FAMILIES.get(sv.autopilot or -1, "unknown")
    name = fd.family if sv.autopilot is None or fd.family != "unknown" else f"MAV_AUTOPILOT {sv.autopilot}"
    versions = [r[1] for r in col.rows.get("AUTOPILOT_VERSION", []) if r[1]]
    fd.autopilot = name + (f" {sw_version(versions[0])}" if versions and not simulated else "")
    fd.vehicle_type = "unknown" if sv.mav_type is None else mav_type_name(sv.mav_type)


def _columns(fd: FlightData, col: Collected, order: tuple[int, ...], w_max: float, ap_comp: int | None) -> None:
    src = tc.choose_sources(fd.counts, fd.family)
    if fd.counts.get("RAW_IMU") and fd.family != "ArduPilot":
        fd.notes.append("RAW_IMU of a non-ArduPilot autopilot holds raw sensor units: not used")
    steps: list[tuple[str, Callable[[str], None]]] = [
        ("imu", lambda s: tc.imu_columns(fd, col, s)),
        ("attitude", lambda s: tc.attitude_columns(fd, col, s)),
        ("velocity", lambda s: tc.velocity_columns(fd, col, s)),
        ("position", lambda s: tc.position_columns(fd, col, s)),
        ("rotors", lambda s: tc.rotor_columns(fd, col, s, order)),
        ("rotor_cmd", lambda s: tc.output_columns(fd, col, s, order, w_max)),
    ]
    for group, build in steps:
        if group in src:
            build(src[group])
            fd.sources[group] = src[group]
    tc.wind_columns(fd, col, ap_comp)
    tc.named_value_columns(fd, col)
    tc.in_air_columns(fd, col)
    tc.battery_gps_columns(fd, col)


def read_tlog(path: Path | str, motor_order: str = "auto", w_max_rad_s: float = 600.0,
              progress: Callable[[float], None] | None = None) -> FlightData:  # fmt: skip
    """Decode a ``.tlog`` (see the module docstring).

    Args:
        path: the log.
        motor_order: ``"auto"`` (the project's order when the log carries the SITL's simulation
            truth, else PX4/ArduPilot quad-X), ``"windseek"`` or ``"quad-x"``.
        w_max_rad_s: rotor speed at full actuator output [rad/s] (rotor commands from PWM).
        progress: called with the fraction of the reading done (0..1).
    """
    path = Path(path)
    size = max(path.stat().st_size, 1)
    sv = survey(path, None if progress is None else (lambda b: progress(0.5 * b / size)))
    if not sv.frames:
        raise ValueError(f"{path}: no MAVLink frames found (not a telemetry log?)")
    fd = FlightData(path=path, kind="tlog", size_bytes=size)
    dialect = ardupilotmega if sv.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA else mavlink
    _vehicle_counts(fd, sv, dialect)
    wanted = {m for m in FIELDS if fd.counts.get(m)}
    col = collect(path, dialect, sv.vehicle, wanted,
                  None if progress is None else (lambda b: progress(0.5 + 0.5 * b / size)))  # fmt: skip
    if sv.skipped:
        fd.notes.append(f"{sv.skipped} byte(s) skipped while resynchronizing on frame starts")
    if sv.truncated:
        fd.warnings.append("the last record is cut off (a truncated log)")
    for what, n in sorted(col.bad.items()):
        fd.notes.append(f"{n} frame(s) skipped: {what}")
    if col.off_clock:
        fd.notes.append(f"{col.off_clock} message(s) with time stamps off the boot clock: "
                        "timed at the latest boot time")  # fmt: skip
    names = {r[1] for r in col.rows.get("NAMED_VALUE_FLOAT", [])}
    simulated = bool(names & set(tc.SIM_TRUTH_NAMES))
    _autopilot(fd, sv, col, simulated)
    motor_order, order = motor_order_of(motor_order, simulated)
    _columns(fd, col, order, w_max_rad_s, None if sv.vehicle is None else sv.vehicle[1])
    fd.texts = sorted(col.texts, key=lambda r: r[0])
    fd.notes.append(f"motor order: {motor_order}")
    return fd


__all__ = ["MOTOR_ORDERS", "motor_order_of", "read_tlog"]
