"""Stream the records of a MAVLink telemetry log (``.tlog``) from disk, and survey who sent what.

Format (pymavlink, MAVProxy, QGroundControl, Mission Planner): a sequence of records, each an 8-byte
big-endian UNIX time in microseconds (when the frame was logged) followed by one MAVLink 1 or 2
frame. :class:`RecordScanner` reads the file in chunks (memory stays bounded for any log size),
splits it into frames and reads each frame's header (message id, system, component) without
decoding the payload; records that do not start with a frame are resynchronized on the next magic
byte and the skipped bytes counted. :func:`survey` is the first pass of :func:`review.tlog.read_tlog`:
it counts frames per (system, component, message id) and decodes only the HEARTBEATs, to find the
vehicle and its autopilot before any payload is decoded.
"""

from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from review.detect import MAGIC_V2, frame_length
from wire.dialect import mavlink

CHUNK_BYTES = 4 << 20
#: The longest record: 8-byte time stamp + the longest MAVLink 2 frame (280 bytes).
MAX_RECORD = 8 + 280
HEARTBEAT_ID = 0
_TS = struct.Struct(">Q")


def frame_header(frame: bytes) -> tuple[int, int, int]:
    """(message id, system id, component id) of a MAVLink 1 or 2 frame."""
    if frame[0] == MAGIC_V2:
        return frame[7] | (frame[8] << 8) | (frame[9] << 16), frame[5], frame[6]
    return frame[5], frame[3], frame[4]


class RecordScanner:
    """Iterate over (log time [s], frame bytes) of a ``.tlog``, reading ``chunk_bytes`` at a time.

    After (or during) the iteration: ``skipped`` bytes were skipped while resynchronizing,
    ``truncated`` is True when the last record was cut off, ``position`` is the bytes consumed.
    ``progress(bytes_done)`` is called once per chunk.
    """

    def __init__(self, path: Path, chunk_bytes: int = CHUNK_BYTES,
                 progress: Callable[[int], None] | None = None) -> None:  # fmt: skip
        self.path = path
        self.chunk_bytes = max(int(chunk_bytes), 2 * MAX_RECORD)
        self.progress = progress
        self.skipped = 0
        self.truncated = False
        self.position = 0

    def __iter__(self) -> Iterator[tuple[float, bytes]]:
        with self.path.open("rb") as f:
            buf = b""
            base = 0  # file offset of buf[0]
            eof = False
            i = 0
            while True:
                if not eof and len(buf) - i < MAX_RECORD:
                    more = f.read(self.chunk_bytes)
                    eof = not more
                    buf, base, i = buf[i:] + more, base + i, 0
                    if self.progress is not None:
                        self.progress(base + len(buf))
                n = len(buf)
                if i + 8 >= n:
                    break
                ln = frame_length(buf, i + 8)
                if ln is None:
                    hits = [k for k in (buf.find(b"\xfe", i + 9), buf.find(b"\xfd", i + 9)) if k >= 0]
                    j = min(hits) if hits else n
                    self.skipped += j - 8 - i
                    i = j - 8
                    continue
                if i + 8 + ln > n:
                    if eof:  # a cut-off last record
                        self.truncated = True
                        self.skipped += n - i
                        i = n
                        break
                    continue  # read more first
                t_us = _TS.unpack_from(buf, i)[0]
                yield t_us * 1e-6, buf[i + 8 : i + 8 + ln]
                i += 8 + ln
            self.position = base + i
            if i < len(buf):  # a record cut off before its frame header
                self.skipped += len(buf) - i
                self.truncated = True


@dataclass
class Survey:
    """The first pass over a tlog: frame counts and the vehicle's identity."""

    counts: Counter[tuple[int, int, int]] = field(default_factory=Counter)  # (sys, comp, msgid) -> frames
    vehicle: tuple[int, int] | None = None  # (system, component) of the first autopilot HEARTBEAT
    autopilot: int | None = None  # its MAV_AUTOPILOT
    mav_type: int | None = None  # its MAV_TYPE
    frames: int = 0
    skipped: int = 0
    truncated: bool = False
    bad_heartbeats: int = 0

    def msg_counts(self, system: int | None, component: int | None = None) -> Counter[int]:
        """Frames per message id of one system (and component), or of all when ``system`` is None."""
        out: Counter[int] = Counter()
        for (s, c, mid), n in self.counts.items():
            if (system is None or s == system) and (component is None or c == component):
                out[mid] += n
        return out


def survey(path: Path, progress: Callable[[int], None] | None = None) -> Survey:
    """Count frames per (system, component, message id) and find the vehicle: the system and
    component of the first HEARTBEAT from an autopilot (not a ground station, not MAV_AUTOPILOT_INVALID)."""
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    sv = Survey()
    scanner = RecordScanner(path, progress=progress)
    counts = sv.counts
    for _, frame in scanner:
        key = frame_header(frame)
        counts[(key[1], key[2], key[0])] += 1
        if key[0] == HEARTBEAT_ID and sv.vehicle is None:
            try:
                m: Any = mav.decode(bytearray(frame))
            except Exception:  # bad CRC or length: counted, never fatal
                sv.bad_heartbeats += 1
                continue
            if m.type != mavlink.MAV_TYPE_GCS and m.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
                sv.vehicle = (key[1], key[2])
                sv.autopilot, sv.mav_type = int(m.autopilot), int(m.type)
    sv.frames = sum(counts.values())
    sv.skipped, sv.truncated = scanner.skipped, scanner.truncated
    return sv


__all__ = ["RecordScanner", "Survey", "frame_header", "survey"]
