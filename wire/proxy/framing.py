"""MAVLink framing for the link proxy: cut a byte stream (TCP) or a datagram into whole frames.

Frames are found by their header alone (start byte, payload length, the signing flag of MAVLink 2),
not decoded and not CRC-checked: the proxy stands in for a link, and a link carries frames of any
dialect, also ones it cannot check (a CRC needs the message's CRC_EXTRA, i.e. its definition).
The receiver's own parser checks them, as it would behind a real link. Bytes that are not the start
of a frame (noise, a truncated frame) are skipped and counted; the pending buffer is bounded by the
largest frame (280 bytes).
"""

from __future__ import annotations

MAVLINK1_STX, MAVLINK2_STX = 0xFE, 0xFD
#: The largest MAVLink 2 frame: 10 header + 255 payload + 2 CRC + 13 signature bytes.
MAX_FRAME = 280


def frame_length(buf: bytes | bytearray, i: int) -> int:
    """Length of the frame starting at ``buf[i]`` (a start byte) once its header is there; 0 before."""
    if buf[i] == MAVLINK2_STX:
        if len(buf) - i < 3:
            return 0
        return 12 + buf[i + 1] + (13 if buf[i + 2] & 0x01 else 0)
    if len(buf) - i < 2:
        return 0
    return 8 + buf[i + 1]


class FrameSplitter:
    """Cuts a byte stream into MAVLink 1/2 frames; ``garbage`` counts the bytes skipped."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.garbage = 0

    def feed(self, data: bytes) -> list[bytes]:
        """The whole frames completed by ``data``, in order (a partial frame waits for the next call)."""
        buf = self._buf
        buf += data
        out: list[bytes] = []
        i = 0
        n = len(buf)
        while i < n:
            if buf[i] not in (MAVLINK1_STX, MAVLINK2_STX):
                j = _next_start(buf, i + 1)
                self.garbage += j - i
                i = j
                continue
            size = frame_length(buf, i)
            if size == 0 or i + size > n:
                break
            out.append(bytes(buf[i : i + size]))
            i += size
        del buf[:i]
        return out

    def flush(self) -> int:
        """Drop a trailing partial frame (the end of a datagram, a closed stream); returns its length."""
        n = len(self._buf)
        self.garbage += n
        self._buf.clear()
        return n


def split_datagram(data: bytes, splitter: FrameSplitter | None = None) -> tuple[list[bytes], int]:
    """The frames of one datagram and the number of bytes that were not part of a whole frame."""
    sp = splitter or FrameSplitter()
    before = sp.garbage
    frames = sp.feed(data)
    sp.flush()
    return frames, sp.garbage - before


def message_ids(data: bytes) -> list[int]:
    """The message ids of the whole frames in ``data`` (a frame or a datagram), from their headers."""
    frames, _ = split_datagram(data)
    return [f[5] if f[0] == MAVLINK1_STX else int.from_bytes(f[7:10], "little") for f in frames]


def _next_start(buf: bytearray, i: int) -> int:
    a, b = buf.find(MAVLINK1_STX, i), buf.find(MAVLINK2_STX, i)
    cands = [x for x in (a, b) if x >= 0]
    return min(cands) if cands else len(buf)
