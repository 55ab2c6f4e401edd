"""PX4's parameter values on the wire: INT32 and REAL32 in PARAM_VALUE / PARAM_SET's float field.

PX4 has exactly two parameter types, ``MAV_PARAM_TYPE_INT32`` and ``MAV_PARAM_TYPE_REAL32``
(``param_type()`` in PX4's parameters library). An INT32 travels *bytewise*: the four bytes of
the int32 are copied into the float field (``memcpy`` in PX4's ``mavlink_parameters.cpp``; PX4
announces ``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``), so INT32 3 arrives as the float
4.2e-45, not 3.0. MAVSDK decodes bytewise for every autopilot but ArduPilot, MAVProxy for
``MAV_AUTOPILOT_PX4``. ArduPilot instead *casts* (3 -> 3.0); this module is PX4's way only.

A float cannot carry every int32 pattern through Python: ints in [-8388608, -4194305] and
[2139095041, 2143289343] are signalling-NaN patterns that a float conversion may alter. The
decoder therefore reads the value from the frame's bytes (:func:`wire_int32`), and the SITL's
INT32 parameters all lie far from those ranges.
"""

from __future__ import annotations

import struct
from typing import Any

from wire.dialect import mavlink as mav

INT32 = mav.MAV_PARAM_TYPE_INT32
REAL32 = mav.MAV_PARAM_TYPE_REAL32
TYPE_NAMES = {INT32: "INT32", REAL32: "REAL32"}

# MAV_PARAM_ERROR values PX4 sends that pymavlink 2.4.50's common.xml does not define yet.
PARAM_ERROR_TYPE_UNSUPPORTED = 6
PARAM_ERROR_TYPE_MISMATCH = 7
PARAM_ERROR_READ_FAIL = 8

_F = struct.Struct("<f")
_I = struct.Struct("<i")


def encode(value: float | int, param_type: int) -> float:
    """The float field of a PARAM_VALUE / PARAM_SET carrying ``value`` of ``param_type`` (PX4 bytewise)."""
    if param_type == INT32:
        return float(_F.unpack(_I.pack(int(value)))[0])
    return float(value)


def decode(field: float, param_type: int) -> float | int:
    """The value carried by a float field of ``param_type`` (inverse of :func:`encode`)."""
    if param_type == INT32:
        return int(_I.unpack(_F.pack(field))[0])
    return float(field)


def wire_int32(msg: Any, payload_offset: int = 0) -> int:
    """The int32 in the 4 bytes at ``payload_offset`` of a received frame's payload, exactly as sent.

    Reads the raw frame (``msg.get_msgbuf()``), so no float conversion can touch a NaN pattern.
    MAVLink 2 trims trailing zero bytes of a payload, so missing bytes are zeros."""
    buf = bytes(msg.get_msgbuf())
    header = 10 if buf[:1] == b"\xfd" else 6
    raw = buf[header + payload_offset:header + payload_offset + 4]
    payload_len = buf[1]
    raw = raw[:max(0, payload_len - payload_offset)].ljust(4, b"\0")
    return int(_I.unpack(raw)[0])


__all__ = ["INT32", "PARAM_ERROR_READ_FAIL", "PARAM_ERROR_TYPE_MISMATCH", "PARAM_ERROR_TYPE_UNSUPPORTED", "REAL32",
           "TYPE_NAMES", "decode", "encode", "wire_int32"]  # fmt: skip
