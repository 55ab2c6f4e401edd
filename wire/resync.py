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

A frame with a valid CRC that fails later (a bad signature) is framed correctly and is not
re-scanned. Datagram links (UDP) hold whole frames and need none of this, but it does no harm there.
Used by the SITL's endpoint and its link to PX4 (serial, TCP), and, through
:func:`resync_connection`, by ``windseek estimator`` and the signing bridge on their ``mavutil``
connections (a real autopilot over a telemetry radio).
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


class ResyncMAVLink(mavlink.MAVLink):
    """The dialect's parser (``robust_parsing`` on) that re-scans the bytes of a frame whose length
    cannot be trusted: ``parse_char`` / ``parse_buffer`` return that frame as pymavlink does (a
    BAD_DATA or UNKNOWN_ message) and carry on from the byte after its start marker. Use it where
    pymavlink's own parser would be: ``ResyncMAVLink(None, sys, comp)``, or as a ``mavutil``
    connection's ``mav`` (:func:`resync_connection`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.robust_parsing = True

    def parse_char(self, c: Any) -> Any:
        m = super().parse_char(c)
        data = getattr(m, "data", b"")  # BAD_DATA and UNKNOWN_ messages carry their whole frame
        if m is not None and _unframed(m) and len(data) > 1:
            self.buf = bytearray(data[1:]) + self.buf[self.buf_index :]
            self.buf_index = 0
            self.expected_length = mavlink.HEADER_LEN_V1 + 2
        return m


def resync_connection(conn: Any) -> Any:
    """Give a fresh ``mavutil`` connection (before any use) a :class:`ResyncMAVLink` parser with the
    connection's identity; returns ``conn``. A serial link through a telemetry radio is where a
    corrupt frame is common and the frames it would swallow matter."""
    old = conn.mav
    conn.mav = ResyncMAVLink(conn, srcSystem=old.srcSystem, srcComponent=old.srcComponent,
                             use_native=False)  # fmt: skip
    return conn
