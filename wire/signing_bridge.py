"""MAVLink 2 signing for a MAVSDK client, which has none: an in-process signing link.

MAVSDK 4.1 (the C++ core behind ``mavsdk.asyncio``) has no message signing: no key option in its
``Configuration``, no ``setup_signing``, and its C MAVLink parser accepts a signed frame without
checking it (``mavlink_signature_check`` passes when no signing is configured), so a MAVSDK client
can neither sign its commands nor reject forged telemetry (MAVSDK issue #1060, "not planned").
What MAVSDK 4 does have is a ``raw://`` connection: the application carries the bytes
(``Mavsdk.subscribe_raw_bytes_to_be_sent`` / ``pass_received_raw_bytes``).

:class:`SigningBridge` is that application: it owns the real link (pymavlink ``mavutil``, any URL
the mission accepts) with signing on, and

- passes to MAVSDK only frames that are correctly signed with the key (bad, unsigned, replayed:
  dropped and counted; PX4's allowlisted unsigned messages are not trusted either), with the
  signature removed (a plain MAVLink 2 frame, CRC recomputed), so MAVSDK never sees a forgery;
- re-packs every frame MAVSDK sends with its own system, component and sequence, signed (pymavlink
  signs; a message our dialect does not define cannot be re-packed: dropped and counted).

Both directions are bounded: a reader thread with a 0.2 s poll, MAVSDK's sends written at once.
"""

from __future__ import annotations

import contextlib
import struct
import threading
from collections import Counter
from typing import Any

from wire import signing
from wire.dialect import mavlink as mav
from wire.resync import resync_connection
from wire.signing import SigningKey
from wire.urls import pymavlink_url


def strip_signature(frame: bytes) -> bytes:
    """A signed MAVLink 2 frame as the unsigned frame (incompat flag cleared, signature cut, CRC recomputed)."""
    from pymavlink.generator.mavcrc import x25crc

    if len(frame) < 12 or frame[0] != 0xFD or not frame[2] & mav.MAVLINK_IFLAG_SIGNED:
        return frame
    n = frame[1]
    header = bytearray(frame[:10])
    header[2] &= ~mav.MAVLINK_IFLAG_SIGNED & 0xFF
    payload = frame[10:10 + n]
    msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
    crc = x25crc(bytes(header[1:]) + payload)
    crc.accumulate(bytes([mav.mavlink_map[msg_id].crc_extra]))
    return bytes(header) + payload + struct.pack("<H", crc.crc)


class SigningBridge:
    """MAVSDK ``raw://`` <-> a signed pymavlink connection (see the module docstring).

    Args:
        core: the ``mavsdk.Mavsdk`` core object (``mavsdk.asyncio.Mavsdk._mavsdk``).
        url: the mission's connection URL (MAVSDK or pymavlink form).
        key: the signing key.
        link_id: our signing link id (the SITL uses 0, the estimator 0 on its own system/component).
    """

    def __init__(self, core: Any, url: str, key: SigningKey, link_id: int = 1) -> None:
        from pymavlink import mavutil

        device, baud = pymavlink_url(url)
        self.core = core
        self.counters: Counter[str] = Counter()
        # The windseek dialect (MAVLink 2, common + ESC_INFO/ESC_STATUS), as windseek estimator does: a
        # MAVLink 1 module would be swapped by mavutil at the first MAVLink 2 frame, losing the signing set-up.
        mavutil.mavlink = mav
        mavutil.current_dialect = "windseek"
        self.conn = resync_connection(mavutil.mavlink_connection(device, baud=baud, autoreconnect=True))
        signing.configure(self.conn.mav, key, link_id, sign_outgoing=False)
        self._enc = mav.MAVLink(None)  # re-packs MAVSDK's frames, signed, with MAVSDK's identity
        signing.configure(self._enc, key, link_id)
        self._out_parser = mav.MAVLink(None)
        self._out_parser.robust_parsing = True
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sub: Any = None

    def start(self) -> SigningBridge:
        self._sub = self.core.subscribe_raw_bytes_to_be_sent(self._from_mavsdk)
        self._thread = threading.Thread(target=self._to_mavsdk, name="signing-bridge", daemon=True)
        self._thread.start()
        return self

    def stats(self) -> dict[str, int]:
        """Counts only (the key is never reported)."""
        return {**self.counters, **signing.counts(self.conn.mav)}

    def _from_mavsdk(self, data: bytes) -> None:
        """MAVSDK's outgoing bytes (its thread): re-pack each frame signed and send it."""
        with self._lock:
            try:
                msgs = self._out_parser.parse_buffer(data) or []
            except Exception:  # noqa: BLE001 - never let a parse error escape into MAVSDK's thread
                self.counters["tx_unparsable"] += 1
                return
            for m in msgs:
                if m.get_type() == "BAD_DATA" or m.get_type().startswith("UNKNOWN_"):
                    self.counters["tx_unsignable"] += 1
                    continue
                enc = self._enc
                enc.srcSystem, enc.srcComponent, enc.seq = m.get_srcSystem(), m.get_srcComponent(), m.get_seq()
                try:
                    self.conn.write(m.pack(enc))
                    self.counters["tx_signed"] += 1
                except (OSError, ValueError):
                    self.counters["tx_errors"] += 1

    def _to_mavsdk(self) -> None:
        """The link's frames (reader thread): only correctly signed ones reach MAVSDK, unsigned."""
        while not self._stop.is_set():
            try:
                m = self.conn.recv_match(blocking=True, timeout=0.2)
            except Exception:  # noqa: BLE001 - a broken read is counted, the loop goes on until stop()
                self.counters["rx_errors"] += 1
                continue
            if m is None:
                continue
            if m.get_type() == "BAD_DATA":
                if "Invalid signature" in str(getattr(m, "reason", "")):
                    self.counters["rx_unauthenticated"] += 1
                else:
                    self.counters["rx_bad"] += 1
                continue
            if not signing.is_authentic(m, True):
                self.counters["rx_unsigned_allowed_dropped"] += 1
                continue
            self.core.pass_received_raw_bytes(strip_signature(bytes(m.get_msgbuf())))
            self.counters["rx_passed"] += 1

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._sub is not None:
            with contextlib.suppress(Exception):  # MAVSDK already destroyed
                self.core.unsubscribe_raw_bytes_to_be_sent(self._sub)
        self.conn.close()
