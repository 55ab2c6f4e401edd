"""Read a MAVLink telemetry log (``.tlog``) into :class:`~review.flight.FlightData`.

Format (pymavlink, MAVProxy, QGroundControl, Mission Planner): a sequence of records, each an
8-byte big-endian UNIX time in microseconds (when the frame was logged) followed by one
MAVLink 1 or 2 frame. Frames are decoded with the project dialect (``wire.dialect``:
common.xml + ESC_INFO/ESC_STATUS), CRC-checked; the ArduPilot WIND message (168, not in
common.xml) is decoded here by hand. Records that do not start with a frame are resynchronized
on the next one; bad CRCs and unknown message ids are counted in the notes, never fatal.

Which messages (the vehicle is the system and component of the first autopilot HEARTBEAT; other
systems, such as the ground station's own heartbeats in a MAVProxy log or a MAVSDK mission's
setpoints and PINGs, are ignored; of the vehicle's other components, such as ``windseek
estimator`` (component 191) or a companion computer, only WIND_COV and STATUSTEXT are kept, so
their HEARTBEATs never count as the autopilot's arming state):

- estimator inputs are decoded by :class:`estimator.mavlink_adapter.MavlinkWindAdapter`, the
  same code that feeds the live estimator, with one source per group chosen from the whole
  log: IMU = the most frequent of HIL_SENSOR / HIGHRES_IMU / SCALED_IMU; attitude =
  ATTITUDE_QUATERNION, else ATTITUDE; velocity = LOCAL_POSITION_NED, else
  GLOBAL_POSITION_INT, else GPS_RAW_INT; rotor speeds = ESC_STATUS, else RAW_RPM.
- without ESC telemetry, rotor commands from SERVO_OUTPUT_RAW (servo1-4) or
  ACTUATOR_OUTPUT_STATUS (actuator 0-3): PWM 1000-2000 us -> 0..w_max (the project SITL's
  mapping; an assumption for other vehicles).
- display: position LOCAL_POSITION_NED (else GLOBAL_POSITION_INT, GPS_RAW_INT on a flat
  earth around the first fix), NAMED_VALUE_FLOAT ``CHEM`` (mg/m^3), the simulation-only
  ``TRUEWN``/``TRUEWE``/``TRUEWD`` (true wind, m/s NED), the autopilot's wind (WIND_COV, or
  ArduPilot WIND: from-direction deg, speed m/s), in-air state (EXTENDED_SYS_STATE landed
  state, else arming), mode and arming changes (HEARTBEAT), STATUSTEXT.

Time: a message's own time stamp (time_usec or time_boot_ms: the autopilot's boot clock);
messages without one (RAW_RPM, HEARTBEAT, EXTENDED_SYS_STATE, STATUSTEXT) take the latest boot
time seen in the autopilot's own messages. The logging wall-clock time is not used (at
``windseek sitl --speed 4`` it runs 4x slower than the boot clock). Time stamps on a UNIX or GPS
epoch (ArduPilot's GPS_RAW_INT) are replaced by the latest boot time. PING's time_usec is the
requester's clock echoed (a MAVSDK client sends its host's monotonic time), never the boot clock:
it is ignored, or a single PING reply would push every later unstamped message (the landed state)
thousands of seconds ahead.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from pathlib import Path

import numpy as np
from pymavlink import mavutil
from pymavlink.generator.mavcrc import x25crc

from estimator.mavlink_adapter import ATT_TYPES, IMU_TYPES, PX4_QUAD_X, SITL_ORDER, VEL_TYPES, MavlinkWindAdapter
from review.flight import MAX_BOOT_TIME_S, FlightData, Input, Series, make_input, pwm_to_fraction, state_changes
from vehicle.frames import euler_to_quat
from wire.dialect import mavlink

MAGIC_V1 = 0xFE
MAGIC_V2 = 0xFD
#: ArduPilot's WIND (ardupilotmega.xml): id, CRC extra, payload <fff = direction deg (from), speed m/s, speed_z m/s.
WIND_ID, WIND_CRC_EXTRA = 168, 1
EARTH_RADIUS_M = 6_371_000.0
#: MAVLink severities -> Rerun text levels.
SEVERITY_LEVEL = {0: "CRITICAL", 1: "CRITICAL", 2: "CRITICAL", 3: "ERROR", 4: "WARN", 5: "INFO", 6: "INFO", 7: "DEBUG"}
#: Motor orders (ESC / output number -> rotor index), see ``estimator.mavlink_adapter``.
MOTOR_ORDERS = {"windseek": SITL_ORDER, "quad-x": PX4_QUAD_X}
SIM_TRUTH_NAMES = ("TRUEWN", "TRUEWE", "TRUEWD")
#: Messages whose time field is not the sender's boot clock: PING echoes the requester's time_usec
#: (MAVSDK sends its host's monotonic clock, thousands of seconds).
FOREIGN_TIME_TYPES = frozenset({"PING"})
#: What other components of the vehicle's system may contribute (an external wind estimator's
#: WIND_COV, a companion's or mission's status texts); everything else comes from the autopilot.
OTHER_COMPONENT_TYPES = frozenset({"WIND_COV", "STATUSTEXT"})


class _Collector:
    """Stands in for the WindEstimator behind MavlinkWindAdapter: records the decoded inputs."""

    t = None

    def __init__(self) -> None:
        self.rows: list[Input] = []
        self.rejected: Counter[str] = Counter()

    def _reject(self, reason: str) -> bool:
        self.rejected[reason] += 1
        return False

    def set_attitude(self, t: float, q: np.ndarray) -> bool:
        self.rows.append(make_input(t, "attitude", np.asarray(q, dtype=float)))
        return True

    def set_rotor_speeds(self, t: float, w: np.ndarray) -> bool:
        self.rows.append(make_input(t, "rotors", np.asarray(w, dtype=float)))
        return True

    def imu(self, t: float, acc: np.ndarray, gyr: np.ndarray | None = None) -> bool:
        g = None if gyr is None else np.asarray(gyr, dtype=float)
        self.rows.append(make_input(t, "imu", (np.asarray(acc, dtype=float), g)))
        return True

    def gnss_velocity(self, t: float, v: np.ndarray) -> bool:
        self.rows.append(make_input(t, "velocity", np.asarray(v, dtype=float)))
        return True


class _ArduWind:
    """ArduPilot WIND decoded by hand (not in the project dialect)."""

    def __init__(self, payload: bytes, src_system: int, src_component: int) -> None:
        p = payload.ljust(12, b"\0")
        self.direction, self.speed, self.speed_z = struct.unpack("<fff", p[:12])
        self._src = src_system
        self._comp = src_component

    def get_type(self) -> str:
        return "WIND"

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        return self._src

    def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
        return self._comp


def _frame_length(buf: bytes, i: int) -> int | None:
    """Length of the MAVLink frame starting at ``buf[i]`` (None if it is not a frame start)."""
    if i + 3 > len(buf):
        return None
    if buf[i] == MAGIC_V2:
        return 12 + buf[i + 1] + (13 if buf[i + 2] & 0x01 else 0)
    if buf[i] == MAGIC_V1:
        return 8 + buf[i + 1]
    return None


def iter_records(data: bytes) -> tuple[list[tuple[float, bytes]], int]:
    """Split tlog bytes into (log time [s], frame bytes) records.

    Returns the records and the number of bytes skipped while resynchronizing (a record not
    followed by a frame start: the next magic byte with 8 bytes before it is tried).
    """
    out: list[tuple[float, bytes]] = []
    i, n, skipped = 0, len(data), 0
    while i + 8 < n:
        ln = _frame_length(data, i + 8)
        if ln is None or i + 8 + ln > n:
            if ln is not None:  # truncated last frame
                skipped += n - i
                break
            j = i + 9
            while j < n and data[j] not in (MAGIC_V1, MAGIC_V2):
                j += 1
            skipped += j - 8 - i
            i = j - 8
            continue
        (ts_us,) = struct.unpack(">Q", data[i : i + 8])
        out.append((ts_us * 1e-6, data[i + 8 : i + 8 + ln]))
        i += 8 + ln
    return out, skipped


def _decode_wind(frame: bytes) -> _ArduWind | None:
    """ArduPilot WIND (id 168) from a raw frame, CRC-checked; None if it is not one."""
    if frame[0] == MAGIC_V2:
        hdr, msgid = 10, frame[7] | (frame[8] << 8) | (frame[9] << 16)
        src, comp = frame[5], frame[6]
    else:
        hdr, msgid, src, comp = 6, frame[5], frame[3], frame[4]
    if msgid != WIND_ID:
        return None
    ln = frame[1]
    crc = x25crc(frame[1 : hdr + ln])
    crc.accumulate(bytes([WIND_CRC_EXTRA]))
    if crc.crc != struct.unpack("<H", frame[hdr + ln : hdr + ln + 2])[0]:
        return None
    return _ArduWind(frame[hdr : hdr + ln], src, comp)


def decode_frames(records: list[tuple[float, bytes]], notes: list[str]) -> list[tuple[float, object]]:
    """Decode frames with the project dialect: (log time [s], pymavlink message) per good frame."""
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    out: list[tuple[float, object]] = []
    bad: Counter[str] = Counter()
    for t_log, frame in records:
        try:
            msg = mav.decode(bytearray(frame))
            mtype = msg.get_type()
        except Exception:  # bad CRC, bad length: counted, never fatal
            msg, mtype = None, "BAD_DATA"
        if mtype.startswith("UNKNOWN_") or msg is None:
            w = _decode_wind(frame)
            if w is not None:
                out.append((t_log, w))
                continue
        if msg is None or mtype == "BAD_DATA":
            bad["bad (CRC or length)"] += 1
        elif mtype.startswith("UNKNOWN_"):
            bad[f"unknown message id {mtype[8:]}"] += 1
        else:
            out.append((t_log, msg))
    for what, n in sorted(bad.items()):
        notes.append(f"{n} frame(s) skipped: {what}")
    return out


def _vehicle_id(msgs: list[tuple[float, object]]) -> tuple[int, int] | None:
    """(system, component) of the first HEARTBEAT from an autopilot (not a ground station)."""
    for _, m in msgs:
        if (
            m.get_type() == "HEARTBEAT"
            and m.type != mavlink.MAV_TYPE_GCS
            and m.autopilot != mavlink.MAV_AUTOPILOT_INVALID
        ):
            return m.get_srcSystem(), m.get_srcComponent()
    return None


def _msg_time(msg: object, t_last: float) -> tuple[float, bool]:
    """(time [s], own?) of a message: its boot-clock stamp, else the latest boot time seen."""
    if msg.get_type() in FOREIGN_TIME_TYPES:
        return t_last, False
    if hasattr(msg, "time_usec"):
        t = msg.time_usec * 1e-6
    elif hasattr(msg, "time_boot_ms"):
        t = msg.time_boot_ms * 1e-3
    else:
        return t_last, False
    if not (0.0 <= t < MAX_BOOT_TIME_S):
        return t_last, False
    return t, True


def _choose_sources(counts: Counter[str]) -> dict[str, str]:
    """One message type per estimator input group (see the module docstring)."""
    src: dict[str, str] = {}
    imu = [m for m in IMU_TYPES if counts[m]]
    if imu:
        src["imu"] = max(imu, key=lambda m: counts[m])
    for group, types in (("attitude", ATT_TYPES), ("velocity", VEL_TYPES), ("rotors", ("ESC_STATUS", "RAW_RPM"))):
        for m in types:
            if counts[m]:
                src[group] = m
                break
    return src


def _autopilot_name(msgs: list[tuple[float, object]], sysid: int | None, sim_truth: bool) -> str:
    if sim_truth:
        return "windseek SITL"
    for _, m in msgs:
        if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == sysid:
            if m.autopilot == mavlink.MAV_AUTOPILOT_PX4:
                return "PX4"
            if m.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
                return "ArduPilot"
            return f"MAV_AUTOPILOT {m.autopilot}"
    return "unknown"


def read_tlog(path: Path | str, motor_order: str = "auto", w_max_rad_s: float = 600.0) -> FlightData:
    """Decode a ``.tlog`` (see the module docstring).

    Args:
        path: the log.
        motor_order: ``"auto"`` (the project's order when the log carries the SITL's
            simulation truth, else PX4/ArduPilot quad-X), ``"windseek"`` or ``"quad-x"``.
        w_max_rad_s: rotor speed at full actuator output [rad/s] (rotor commands from PWM).
    """
    path = Path(path)
    fd = FlightData(path=path, kind="tlog")
    records, skipped = iter_records(path.read_bytes())
    if skipped:
        fd.notes.append(f"{skipped} byte(s) skipped while resynchronizing on frame starts")
    msgs = decode_frames(records, fd.notes)
    if not msgs:
        raise ValueError(f"{path}: no MAVLink frames found (not a telemetry log?)")
    vid = _vehicle_id(msgs)
    sysid = None if vid is None else vid[0]
    if vid is None:
        fd.notes.append("no autopilot HEARTBEAT: messages of every system used")
    else:
        others = sum(1 for _, m in msgs if m.get_srcSystem() != sysid)
        if others:
            fd.notes.append(f"{others} message(s) of systems other than the vehicle ({sysid}) ignored")
        msgs = [(t, m) for t, m in msgs if m.get_srcSystem() == sysid]
        # Other components of the vehicle's system (an external estimator, a companion computer): their
        # HEARTBEATs are not the autopilot's arming state and their time stamps are not its clock.
        comp = [(t, m) for t, m in msgs if m.get_srcComponent() == vid[1] or m.get_type() in OTHER_COMPONENT_TYPES]
        if len(comp) < len(msgs):
            fd.notes.append(f"{len(msgs) - len(comp)} message(s) of components other than the autopilot "
                            f"({sysid}:{vid[1]}) ignored")  # fmt: skip
        msgs = comp
    ap_comp = None if vid is None else vid[1]
    for _, m in msgs:
        fd.counts[m.get_type()] += 1
    names = {m.name for _, m in msgs if m.get_type() == "NAMED_VALUE_FLOAT"}
    sim_truth = bool(names & set(SIM_TRUTH_NAMES))
    fd.autopilot = _autopilot_name(msgs, sysid, sim_truth)
    if motor_order == "auto":
        motor_order = "windseek" if sim_truth else "quad-x"
    if motor_order not in MOTOR_ORDERS:
        raise ValueError(f"motor_order = {motor_order!r}: allowed values are auto, {', '.join(MOTOR_ORDERS)}")
    order = MOTOR_ORDERS[motor_order]

    collector = _Collector()
    adapter = MavlinkWindAdapter(collector, esc_to_rotor=order)  # type: ignore[arg-type]
    fd.sources.update(_choose_sources(fd.counts))
    adapter.sources.update(fd.sources)
    out_src = "SERVO_OUTPUT_RAW" if fd.counts["SERVO_OUTPUT_RAW"] else (
        "ACTUATOR_OUTPUT_STATUS" if fd.counts["ACTUATOR_OUTPUT_STATUS"] else None)  # fmt: skip
    if out_src and "rotors" not in fd.sources:
        fd.sources["rotor_cmd"] = out_src
    pos_src = next((m for m in ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT") if fd.counts[m]), None)
    if pos_src:
        fd.sources["position"] = pos_src

    t_last = 0.0
    pos_rows: list[tuple[float, np.ndarray]] = []
    att_rows: list[tuple[float, np.ndarray]] = []
    chem_rows: list[tuple[float, float]] = []
    truth_parts: dict[int, dict[str, float]] = {}
    apw_rows: list[tuple[float, np.ndarray]] = []
    cmd_rows: list[tuple[float, np.ndarray]] = []
    landed: list[tuple[float, bool]] = []
    armed: list[tuple[float, bool]] = []
    geo0: tuple[float, float, float] | None = None
    last_mode: str | None = None
    bad_time = 0
    wind_comps: set[int] = set()
    for _, m in msgs:
        mtype = m.get_type()
        t, own = _msg_time(m, t_last)
        if own:
            if ap_comp is None or m.get_srcComponent() == ap_comp:
                t_last = max(t_last, t)  # only the autopilot's stamps move its clock
        elif (hasattr(m, "time_usec") or hasattr(m, "time_boot_ms")) and mtype not in FOREIGN_TIME_TYPES:
            bad_time += 1
        adapter.t_last = t_last
        if mtype == fd.sources.get("attitude"):
            if mtype == "ATTITUDE_QUATERNION":
                att_rows.append((t, np.array([m.q1, m.q2, m.q3, m.q4], dtype=float)))
            elif all(math.isfinite(v) for v in (m.roll, m.pitch, m.yaw)):
                att_rows.append((t, euler_to_quat(m.roll, m.pitch, m.yaw)))
        if own or mtype in ("RAW_RPM", "ESC_INFO"):
            adapter.handle(m)
        if mtype == pos_src:
            if mtype == "LOCAL_POSITION_NED":
                pos_rows.append((t, np.array([m.x, m.y, m.z], dtype=float)))
            else:
                if mtype == "GLOBAL_POSITION_INT":
                    lat, lon, alt = m.lat * 1e-7, m.lon * 1e-7, m.relative_alt * 1e-3
                else:
                    if m.fix_type < 3:
                        continue
                    lat, lon, alt = m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3
                if geo0 is None:
                    geo0 = (lat, lon, alt if mtype == "GPS_RAW_INT" else 0.0)
                n = math.radians(lat - geo0[0]) * EARTH_RADIUS_M
                e = math.radians(lon - geo0[1]) * EARTH_RADIUS_M * math.cos(math.radians(geo0[0]))
                pos_rows.append((t, np.array([n, e, -(alt - geo0[2])])))
        elif mtype == "NAMED_VALUE_FLOAT":
            if m.name == "CHEM":
                chem_rows.append((t, float(m.value)))
            elif m.name in SIM_TRUTH_NAMES:
                truth_parts.setdefault(m.time_boot_ms, {})[m.name] = float(m.value)
        elif mtype == "WIND_COV":
            wind_comps.add(m.get_srcComponent())
            apw_rows.append((t, np.array([m.wind_x, m.wind_y, m.wind_z], dtype=float)))
        elif mtype == "WIND":
            d = math.radians(m.direction)
            apw_rows.append((t, np.array([-m.speed * math.cos(d), -m.speed * math.sin(d), math.nan])))
        elif mtype == out_src and mtype == fd.sources.get("rotor_cmd"):
            raw = [m.servo1_raw, m.servo2_raw, m.servo3_raw, m.servo4_raw] if mtype == "SERVO_OUTPUT_RAW" else list(
                m.actuator[:4])  # fmt: skip
            frac = pwm_to_fraction(np.array(raw, dtype=float))
            w = np.zeros(4)
            for k, r in enumerate(order):
                w[r] = frac[k] * w_max_rad_s
            cmd_rows.append((t, w))
        elif mtype == "EXTENDED_SYS_STATE":
            if m.landed_state != mavlink.MAV_LANDED_STATE_UNDEFINED:
                in_air = m.landed_state in (mavlink.MAV_LANDED_STATE_IN_AIR, mavlink.MAV_LANDED_STATE_LANDING)
                landed.append((t, in_air))
        elif mtype == "HEARTBEAT":
            is_armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            if not armed or armed[-1][1] != is_armed:
                fd.texts.append((t, "armed" if is_armed else "disarmed", "INFO"))
            armed.append((t, is_armed))
            mode = mavutil.mode_string_v10(m)
            if mode != last_mode:
                fd.texts.append((t, f"mode {mode}", "INFO"))
                last_mode = mode
        elif mtype == "STATUSTEXT":
            who = "" if m.get_srcComponent() == ap_comp or ap_comp is None else f"[{m.get_srcComponent()}] "
            fd.texts.append((t, who + str(m.text), SEVERITY_LEVEL.get(m.severity, "INFO")))

    rows = [r for r in collector.rows if r.t < MAX_BOOT_TIME_S]
    if len(rows) < len(collector.rows):
        fd.notes.append(f"{len(collector.rows) - len(rows)} input(s) with time stamps off the boot clock dropped")
    if bad_time:
        fd.notes.append(f"{bad_time} message(s) with time stamps off the boot clock: timed at the latest boot time")
    if collector.rejected:
        fd.notes.append(f"inputs rejected while decoding: {dict(collector.rejected)}")
    rows += [make_input(t, "rotor_cmd", w) for t, w in cmd_rows]
    fd.inputs = rows
    fd.sort_inputs()
    fd.position = Series.from_rows(pos_rows, "position", 3)
    fd.attitude = Series.from_rows(att_rows, "attitude", 4)
    fd.chem = Series.from_rows(chem_rows, "chem")
    if chem_rows:
        fd.sources["chem"] = "NAMED_VALUE_FLOAT CHEM"
    truth = [(ms * 1e-3, np.array([p[n] for n in SIM_TRUTH_NAMES])) for ms, p in truth_parts.items()
             if all(n in p for n in SIM_TRUTH_NAMES)]  # fmt: skip
    fd.truth_wind = Series.from_rows(truth, "truth", 3)
    if truth:
        fd.sources["truth"] = "NAMED_VALUE_FLOAT TRUEWN/TRUEWE/TRUEWD"
    fd.autopilot_wind = Series.from_rows(apw_rows, "autopilot", 3)
    if apw_rows:
        fd.sources["autopilot_wind"] = "WIND_COV" if fd.counts["WIND_COV"] else "WIND"
        if wind_comps - {ap_comp, None}:
            fd.sources["autopilot_wind"] += " (component " + ", ".join(map(str, sorted(wind_comps))) + ")"
    rot = [(r.t, r.value) for r in fd.inputs if r.kind == "rotors"] or cmd_rows
    fd.rotors = Series.from_rows(rot, "rotors", 4)
    if landed:
        fd.in_air = state_changes(landed)
        fd.sources["in_air"] = "EXTENDED_SYS_STATE"
    elif armed:
        fd.in_air = state_changes(armed)
        fd.sources["in_air"] = "HEARTBEAT (armed)"
    fd.notes.append(f"motor order: {motor_order}")
    return fd


__all__ = ["MOTOR_ORDERS", "decode_frames", "iter_records", "read_tlog"]
