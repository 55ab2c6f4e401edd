"""Parse a MAVLink byte stream (serial, TCP) and resynchronise after a corrupt frame.

pymavlink's parser, like the MAVLink C library, trusts a frame's length byte: a stray 0xFD or
0xFE (line noise, a truncated frame, garbage from a peer) followed by a length swallows that
many bytes of the good frames that follow, and the CRC failure throws them all away. On a link
that waits for one answer per step (PX4's lockstep HIL_ACTUATOR_CONTROLS) each swallowed answer
cost a bounded wait, and a stray marker inside the swallowed bytes started the next swallow (four
lost answers in a row seen in 1 of 25 runs). Here a frame that fails its CRC (or carries unknown
incompatibility flags, or a message id the dialect does not know, so that its CRC cannot be
checked) is dropped, and parsing starts again at the byte after its start marker, so any good
frame inside it is found. The unknown message itself is still reported; re-scanning its bytes
adds at most a few "Bad prefix" reports. Every step moves at least one byte forward: hostile input
costs at most the longest frame (280 bytes) of re-scanning per marker byte, never a hang.

Frames with a valid CRC that fail later (a bad signature, an unknown message id) are framed
correctly and are not re-scanned. Datagram links (UDP) hold whole frames and need none of this.
"""

from __future__ import annotations

from typing import Any

from wire.dialect import mavlink

#: BAD_DATA reasons that mean the frame's length cannot be trusted.
_UNFRAMED = ("invalid MAVLink CRC", "invalid incompat_flags", "Unable to unpack MAVLink CRC")


def _unframed(m: Any) -> bool:
    """True for a frame whose length cannot be trusted: a failed CRC, or a message id this dialect
    does not know (its CRC cannot be checked: a stray marker's "frame" mostly reads as one)."""
    mtype = m.get_type()
    if mtype.startswith("UNKNOWN_"):
        return True
    return mtype == "BAD_DATA" and any(r in str(getattr(m, "reason", "")) for r in _UNFRAMED)


def parse_stream(parser: Any, data: bytes) -> list[Any]:
    """Every message (BAD_DATA included, as pymavlink reports it) that ``data`` completes on
    ``parser`` (a pymavlink ``MAVLink`` with ``robust_parsing``); after a frame whose length cannot
    be trusted, its bytes after the start marker are parsed again."""
    out: list[Any] = []
    m = parser.parse_char(data)
    while m is not None:
        out.append(m)
        if _unframed(m) and len(m.data) > 1:
            rest = bytes(m.data[1:]) + bytes(parser.buf[parser.buf_index :])
            parser.buf, parser.buf_index = bytearray(), 0
            parser.expected_length = mavlink.HEADER_LEN_V1 + 2
            m = parser.parse_char(rest)
        else:
            m = parser.parse_char(b"")
    return out
