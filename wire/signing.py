"""MAVLink 2 message signing for every link the project owns (issue 14.5).

One shared 32-byte secret key, given to every program the same way: ``--signing-key FILE`` (the
file holds the key as 64 hexadecimal characters; whitespace and a trailing newline are ignored) or
the environment variable ``WINDSEEK_SIGNING_KEY`` (the same hex string). The option wins over the
variable. With a key, a program signs everything it sends and drops, and counts, every frame that
is unsigned or wrongly signed (bad signature, replayed or stale time stamp: pymavlink's checks),
except the few messages PX4 accepts unsigned (:data:`UNSIGNED_ALLOWED`).

PX4 (since its signing support, PX4-Autopilot #25284) keeps the key in
``/mavlink/mavlink-signing-key.bin`` on the SD card (32-byte key + 8-byte time stamp), provisioned
with SETUP_SIGNING; a key present means signed output and enforced input on every link. Earlier
revisions of that work had ``MAV_SIGN_CFG`` (0 signing optional, 1 required except on USB,
2 required everywhere); windseek's key on the command line behaves like a provisioned key with
``MAV_SIGN_CFG`` = 2. PX4's unsigned allowlist is RADIO_STATUS, ADSB_VEHICLE, COLLISION and, in
its documentation, HEARTBEAT; windseek accepts the same four unsigned, and an unsigned HEARTBEAT
never counts as a live ground link for the data-link failsafe.

The key is secret: :class:`SigningKey` never shows it (``repr``/``str`` name only its source),
errors never quote it, and nothing here writes it anywhere.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import string
import struct
import time
import types
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ENV_VAR = "WINDSEEK_SIGNING_KEY"
KEY_BYTES = 32
#: Message ids accepted unsigned while signing is on, as PX4: HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION.
UNSIGNED_ALLOWED = frozenset({0, 109, 246, 247})
#: MAVLink signing time stamps count 10 us units since 2015-01-01 00:00:00 UTC.
_EPOCH_2015 = 1420070400
SETUP_SIGNING_ID = 256
_TS = struct.Struct("<IH")


class SigningKeyError(ValueError):
    """A key that cannot be used; the message names the source, never the key."""


@dataclass(frozen=True)
class SigningKey:
    """The 32-byte secret and where it came from. ``repr``/``str`` show the source only."""

    secret: bytes = field(repr=False)
    source: str

    def __repr__(self) -> str:
        return f"SigningKey(from {self.source})"

    __str__ = __repr__


def parse_key(text: str, source: str) -> SigningKey:
    """A key from its hex text (64 hexadecimal characters); SigningKeyError otherwise."""
    hexkey = "".join(text.split())
    if len(hexkey) != 2 * KEY_BYTES:
        raise SigningKeyError(f"signing key from {source}: expected {2 * KEY_BYTES} hexadecimal characters "
                              f"(a {KEY_BYTES}-byte key), found {len(hexkey)}")  # fmt: skip
    if any(c not in string.hexdigits for c in hexkey):
        raise SigningKeyError(f"signing key from {source}: only hexadecimal characters 0-9 a-f are allowed")
    secret = bytes.fromhex(hexkey)
    if secret == bytes(KEY_BYTES):
        # MAVLink's all-zero key means "signing off" (SETUP_SIGNING): refuse it rather than sign with it.
        raise SigningKeyError(f"signing key from {source}: the all-zero key is not a key")
    return SigningKey(secret, source)


def load_key(path: str | None, environ: Mapping[str, str] | None = None) -> SigningKey | None:
    """The key from ``--signing-key FILE``, else from ``WINDSEEK_SIGNING_KEY``, else None (no signing)."""
    env = os.environ if environ is None else environ
    if path:
        source = f"file {path}"
        try:
            text = Path(path).read_text(encoding="ascii")
        except (OSError, UnicodeDecodeError) as e:
            reason = e.strerror if isinstance(e, OSError) and e.strerror else "not an ASCII text file"
            raise SigningKeyError(f"signing key {source}: cannot read it ({reason})") from None
        return parse_key(text, source)
    value = env.get(ENV_VAR)
    if value:
        return parse_key(value, f"environment variable {ENV_VAR}")
    return None


def timestamp_now() -> int:
    """The signing time stamp of now (10 us units since 2015-01-01)."""
    return int((time.time() - _EPOCH_2015) * 100_000)


def allow_unsigned(_mav: Any, msg_id: int) -> bool:
    """pymavlink's ``allow_unsigned_callback``: PX4's unsigned allowlist."""
    return msg_id in UNSIGNED_ALLOWED


def check_signature_first(mav: Any, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
    """pymavlink's ``check_signature`` with the order fixed: the signature is verified *before* the time
    stamp is recorded. pymavlink 2.4.50 records a stream's time stamp first, so one forged frame with a
    far-future time stamp and a victim's (link, system, component) locks that victim out (every genuine
    frame then looks replayed). Time-stamp rules unchanged: strictly increasing per stream, a new stream
    at most one minute behind our clock; a good frame advances our clock."""
    s = mav.signing
    h = hashlib.sha256()
    h.update(s.secret_key)
    h.update(bytes(msgbuf[:-6]))
    if not hmac.compare_digest(h.digest()[:6], bytes(msgbuf[-6:])):
        return False
    tlow, thigh = _TS.unpack(bytes(msgbuf[-12:-6]))
    timestamp = tlow + (thigh << 32)
    stream = (msgbuf[-13], src_system, src_component)
    last = s.stream_timestamps.get(stream)
    if (last is not None and timestamp <= last) or (last is None and timestamp + 6_000_000 < s.timestamp):
        return False
    s.stream_timestamps[stream] = timestamp
    s.timestamp = max(s.timestamp, timestamp)
    return True


def configure(mav: Any, key: SigningKey, link_id: int = 0, sign_outgoing: bool = True) -> None:
    """Sign with ``key`` on a pymavlink ``MAVLink`` object and verify what it parses (PX4's allowlist,
    :func:`check_signature_first`)."""
    s = mav.signing
    s.secret_key = key.secret
    s.link_id = int(link_id) & 0xFF
    s.timestamp = max(int(s.timestamp or 0), timestamp_now())
    s.sign_outgoing = sign_outgoing
    s.allow_unsigned_callback = allow_unsigned
    mav.check_signature = types.MethodType(check_signature_first, mav)


def configure_connection(conn: Any, key: SigningKey, link_id: int = 0) -> None:
    """Signing on a ``mavutil.mavlink_connection`` (its ``setup_signing``, PX4's allowlist)."""
    conn.setup_signing(key.secret, sign_outgoing=True, allow_unsigned_callback=allow_unsigned,
                       initial_timestamp=timestamp_now(), link_id=int(link_id) & 0xFF)  # fmt: skip
    conn.mav.check_signature = types.MethodType(check_signature_first, conn.mav)


def counts(mav: Any) -> dict[str, int]:
    """What the verifier of a pymavlink ``MAVLink`` object saw: signed frames accepted, bad signatures,
    unsigned frames accepted by the allowlist, frames rejected (unsigned or bad, not allowlisted)."""
    s = mav.signing
    return {"signed_ok": int(s.goodsig_count), "bad_signature": int(s.badsig_count),
            "unsigned_allowed": int(s.unsigned_count), "rejected": int(s.reject_count)}  # fmt: skip


def is_authentic(msg: Any, signing_on: bool) -> bool:
    """True if ``msg`` may be trusted as coming from a key holder: always without signing, else only a
    correctly signed frame (an allowlisted unsigned one is accepted, not trusted)."""
    return not signing_on or bool(getattr(msg, "_signed", False))


__all__ = ["ENV_VAR", "KEY_BYTES", "SETUP_SIGNING_ID", "UNSIGNED_ALLOWED", "SigningKey", "SigningKeyError",
           "allow_unsigned", "check_signature_first", "configure", "configure_connection", "counts",
           "is_authentic", "load_key", "parse_key", "timestamp_now"]  # fmt: skip
