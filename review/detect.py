"""Which kind of log a file is, by its content (the suffix is only a hint people get wrong).

- PX4 ULog: the 7-byte magic ``ULog`` 0x01 0x12 0x35 (PX4 "ULog File Format").
- ArduPilot DataFlash binary log (``.bin``): messages start with HEAD1 0xA3, HEAD2 0x95, and the
  first one is the FMT message (type 0x80) that defines FMT itself.
- MAVLink telemetry log (``.tlog``): records of an 8-byte big-endian time stamp followed by one
  MAVLink 1 (0xFE) or MAVLink 2 (0xFD) frame; recognised when three consecutive records chain up
  (each frame's length leads to the next record's magic byte) within the first bytes.
"""

from __future__ import annotations

from pathlib import Path

ULOG_MAGIC = b"ULog\x01\x12\x35"
DATAFLASH_MAGIC = b"\xa3\x95\x80"
MAGIC_V1, MAGIC_V2 = 0xFE, 0xFD
#: How far into the file a tlog's first record may start (a writer's junk or a cut-off record).
TLOG_SEARCH_BYTES = 4096
KINDS = ("tlog", "ulog", "dataflash")


def frame_length(buf: bytes | bytearray | memoryview, i: int) -> int | None:
    """Length [bytes] of the MAVLink frame starting at ``buf[i]`` (None if no frame starts there)."""
    if i + 3 > len(buf):
        return None
    if buf[i] == MAGIC_V2:
        return 12 + buf[i + 1] + (13 if buf[i + 2] & 0x01 else 0)
    if buf[i] == MAGIC_V1:
        return 8 + buf[i + 1]
    return None


def _chains(head: bytes, start: int, records: int = 3) -> bool:
    """True when ``records`` tlog records chain up from ``start`` (fewer when the data end cleanly
    after a record, or a later record is cut off by the end of ``head``)."""
    i = start
    for k in range(records):
        if i == len(head) and k > 0:
            return True
        ln = frame_length(head, i + 8)
        if ln is None:
            return False
        i += 8 + ln
        if i > len(head):
            return k > 0
    return True


def looks_like_tlog(head: bytes) -> bool:
    """True when a MAVLink telemetry log's records start within the first :data:`TLOG_SEARCH_BYTES`."""
    for start in range(0, min(len(head) - 9, TLOG_SEARCH_BYTES)):
        if head[start + 8] in (MAGIC_V1, MAGIC_V2) and _chains(head, start):
            return True
    return False


def detect_format(path: Path | str) -> str:
    """``"ulog"``, ``"dataflash"`` or ``"tlog"`` from the file's first bytes.

    Raises:
        FileNotFoundError: no such file.
        IsADirectoryError: the path is a directory.
        ValueError: an empty file, or none of the three formats.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a directory, not a log file (give one .tlog, .ulg or .bin)")
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    with path.open("rb") as f:
        head = f.read(64 * 1024)
    if not head:
        raise ValueError(f"{path}: empty file")
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(DATAFLASH_MAGIC):
        return "dataflash"
    if looks_like_tlog(head):
        return "tlog"
    hint = ""
    if head[:1].isascii() and b"FMT," in head[:4096]:
        hint = " (an ArduPilot DataFlash text log? convert it to .bin or review the .bin)"
    raise ValueError(f"{path}: not a PX4 ULog, ArduPilot DataFlash or MAVLink telemetry log{hint}")


__all__ = ["DATAFLASH_MAGIC", "KINDS", "ULOG_MAGIC", "detect_format", "frame_length", "looks_like_tlog"]
