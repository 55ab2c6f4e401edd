"""Read a PX4 ULog (``.ulg``) into :class:`~review.flight.FlightData` with ``pyulog``.

pyulog loads only the topics the review uses (:data:`TOPICS`) into numpy columns; the topics are
converted in :mod:`review.ulog_topics`. pyulog reads the whole file at once (no streaming), at about
10-20 MB/s here. It prints its complaints about a damaged file ("File corruption detected ...") to
stdout: they are captured and reported as :attr:`FlightData.warnings` (stderr of ``windseek review``),
so that ``--json`` output stays JSON. A file cut inside a message (a truncated log), which pyulog reads up
to the cut without a word, gets a warning too (:func:`is_cut_off`), as for a tlog.

In-air state: ``vehicle_land_detected.landed``; without a land detector, arming
(``vehicle_status.arming_state``); without either, the vehicle counts as never airborne.
"""

from __future__ import annotations

import contextlib
import io
import mmap
import struct
from pathlib import Path

import numpy as np
from pyulog import ULog

from review import ulog_topics as ut
from review.flight import FlightData
from review.tlog import motor_order_of
from review.vehicle_info import PX4_VEHICLE_TYPES, mav_type_name, sw_version

TOPICS = [
    "sensor_combined",
    "vehicle_attitude",
    "vehicle_local_position",
    "sensor_gps",
    "vehicle_gps_position",
    "esc_status",
    "actuator_outputs",
    "wind",
    "wind_estimate",
    "vehicle_land_detected",
    "vehicle_status",
    "debug_key_value",
    "battery_status",
]
#: ULog logging levels (syslog) -> Rerun text levels.
LOG_LEVELS = {"EMERGENCY": "CRITICAL", "ALERT": "CRITICAL", "CRITICAL": "CRITICAL", "ERROR": "ERROR",
              "WARNING": "WARN", "NOTICE": "INFO", "INFO": "INFO", "DEBUG": "DEBUG"}  # fmt: skip


class ParserStuckError(RuntimeError):
    """pyulog kept reading without getting through the file (not one of the errors pyulog catches)."""


class BoundedFile:
    """The log file for pyulog, with a bound on its read calls.

    pyulog steps back over a message it finds corrupt (``seek(-2 - msg_size, 1)``, to advance by one
    byte); when that message's payload was cut by the end of the file the seek goes back further than
    the reads went forward, and pyulog loops forever (seen on a truncated, damaged ULog). A legitimate
    parse makes at most two reads per 3-byte message header plus two per byte skipped while
    resynchronizing, so ``8 * size + 100_000`` read calls is a bound that no readable file reaches.
    """

    def __init__(self, path: Path) -> None:
        self._f = path.open("rb")
        self._left = 8 * path.stat().st_size + 100_000

    def read(self, n: int = -1) -> bytes:
        self._left -= 1
        if self._left < 0:
            raise ParserStuckError("pyulog did not get through the file (a damaged or truncated log)")
        return self._f.read(n)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._f.seek(offset, whence)

    def tell(self) -> int:
        return self._f.tell()

    def close(self) -> None:
        self._f.close()


def open_ulog(path: Path) -> tuple[ULog, list[str]]:
    """pyulog's ULog of the review's topics, and what pyulog printed (its corruption warnings)."""
    out = io.StringIO()
    f = BoundedFile(path)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            ulog = ULog(f, TOPICS)
    except Exception as e:  # pyulog raises plain exceptions on a bad header
        raise ValueError(f"{path}: not a readable ULog ({e})") from e
    finally:
        f.close()
    return ulog, [line.strip() for line in out.getvalue().splitlines() if line.strip()]


#: ULog file header: magic (7 bytes), version (1), timestamp (8); then messages of [uint16 size][uint8 type][payload].
ULOG_HEADER_BYTES, MSG_HEADER_BYTES = 16, 3


def is_cut_off(path: Path) -> bool:
    """True when the file ends inside a message (a truncated log: the last message's header or payload
    runs past the end). pyulog stops there without a word ("File is most likely cut"), so the message
    headers are walked here; only meaningful on a file pyulog found undamaged (a corrupt stretch
    desynchronizes the walk)."""
    with path.open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
        size, pos = len(m), ULOG_HEADER_BYTES
        while pos + MSG_HEADER_BYTES <= size:
            pos += MSG_HEADER_BYTES + struct.unpack_from("<H", m, pos)[0]
        return pos != size


def _identity(fd: FlightData, ulog: ULog, data: dict[str, ut.Topic]) -> None:
    """Autopilot name and version (``ver_sw_release`` decoded, else the git hash), and the vehicle type."""
    info = ulog.msg_info_dict
    fd.family = "PX4"
    release = info.get("ver_sw_release")
    ver = sw_version(release) if release else ""
    git = str(info.get("ver_sw", ""))[:8]
    fd.autopilot = " ".join(s for s in (str(info.get("sys_name") or "PX4"), ver, f"({git})" if git else "") if s)
    mav_type = ulog.initial_parameters.get("MAV_TYPE")
    status = data.get("vehicle_status", {})
    if mav_type is None and "system_type" in status and len(status["system_type"]):
        mav_type = int(status["system_type"][0])
    if mav_type is not None:
        fd.vehicle_type = mav_type_name(int(mav_type))
    elif "vehicle_type" in status and len(status["vehicle_type"]):
        fd.vehicle_type = PX4_VEHICLE_TYPES.get(int(status["vehicle_type"][0]), "unknown")
    if "is_vtol" in status and np.any(status["is_vtol"]) and "VTOL" not in fd.vehicle_type:
        fd.vehicle_type = f"VTOL ({fd.vehicle_type})"


def _file_notes(fd: FlightData, ulog: ULog, printed: list[str]) -> None:
    if ulog.file_corruption or printed:
        lines = list(dict.fromkeys(printed))
        what = "; ".join(lines[:3]) + (f" (and {len(lines) - 3} more)" if len(lines) > 3 else "") or "file corruption"
        fd.warnings.append(f"pyulog: {what}: data after the damage may be missing")
    elif is_cut_off(Path(fd.path)):
        fd.warnings.append("the last message is cut off (a truncated log)")
    if ulog.dropouts:
        fd.notes.append(f"{len(ulog.dropouts)} logger dropout(s), {sum(d.duration for d in ulog.dropouts)} ms in all")


def _topics(fd: FlightData, data: dict[str, ut.Topic], order: tuple[int, ...], w_max: float) -> None:
    if (d := data.get("sensor_combined")) is not None:
        ut.imu_topic(fd, d)
    if (d := data.get("vehicle_attitude")) is not None:
        ut.attitude_topic(fd, d)
    if (d := data.get("vehicle_local_position")) is not None:
        ut.local_position_topic(fd, d)
    if "velocity" not in fd.sources:
        any(ut.gps_velocity_topic(fd, n, data[n]) for n in ("sensor_gps", "vehicle_gps_position") if n in data)
    if (d := data.get("esc_status")) is not None:
        ut.esc_topic(fd, d, order)
    if "rotors" not in fd.sources and (d := data.get("actuator_outputs")) is not None:
        ut.outputs_topic(fd, d, order, w_max)
    any(ut.wind_topic(fd, n, data[n]) for n in ("wind", "wind_estimate") if n in data)
    land = (d := data.get("vehicle_land_detected")) is not None and ut.land_topic(fd, d)
    if (d := data.get("vehicle_status")) is not None:
        ut.status_topic(fd, d, land_detector=land)
    if (d := data.get("debug_key_value")) is not None:
        ut.chem_topic(fd, d)
    if (d := data.get("battery_status")) is not None:
        ut.battery_topic(fd, d)
    any(ut.gps_topic(fd, n, data[n]) for n in ("vehicle_gps_position", "sensor_gps") if n in data)
    if (d := data.get("vehicle_local_position")) is not None:
        ut.gps_origin(fd, d)


def read_ulog(path: Path | str, motor_order: str = "quad-x", w_max_rad_s: float = 600.0) -> FlightData:
    """Decode a ``.ulg`` (see the module docstring).

    Args:
        path: the log.
        motor_order: ``"quad-x"`` (PX4, default) or ``"windseek"`` (ESC i = rotor i); ``"auto"``
            means quad-x here.
        w_max_rad_s: rotor speed at full actuator output [rad/s] (rotor commands from outputs).
    """
    path = Path(path)
    motor_order, order = motor_order_of("quad-x" if motor_order == "auto" else motor_order, False)
    ulog, printed = open_ulog(path)
    fd = FlightData(path=path, kind="ulog", size_bytes=path.stat().st_size)
    data: dict[str, ut.Topic] = {}
    for ds in ulog.data_list:
        fd.counts[ds.name if ds.multi_id == 0 else f"{ds.name}[{ds.multi_id}]"] += len(ds.data["timestamp"])
        if ds.multi_id == 0 and ds.name not in data:
            data[ds.name] = ds.data
    _identity(fd, ulog, data)
    _file_notes(fd, ulog, printed)
    _topics(fd, data, order, w_max_rad_s)
    for m in ulog.logged_messages:
        fd.texts.append((m.timestamp * 1e-6, m.message, LOG_LEVELS.get(m.log_level_str(), "INFO")))
    fd.texts.sort(key=lambda r: r[0])
    fd.notes.append(f"motor order: {motor_order}")
    return fd


__all__ = ["TOPICS", "is_cut_off", "open_ulog", "read_ulog"]
