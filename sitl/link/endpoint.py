"""The MAVLink endpoint: frames in and out over several transports, with per-link parsers.

Every transport is a *link* with its own MAVLink parser (a byte stream's parse state must not
mix with another's). Incoming messages are dispatched by type to handlers; answers to a request go
back to the peer that asked (:meth:`Endpoint.reply`: on its link and, on UDP, to its address only),
streams go to every link. Anything that cannot be parsed (bad CRC, truncated or unknown frames,
garbage) is counted in :attr:`Endpoint.counters` and dropped; a handler that raises is counted too
and never stops the endpoint.

With a signing key (:mod:`wire.signing`) every frame sent is signed and every frame received must
be signed with the key: an unsigned or wrongly signed frame (bad signature, replayed or stale time
stamp) is dropped before any handler, hook, forwarder or log sees it, and counted
(``rx_unauthenticated``), except PX4's unsigned allowlist. A MAVLink 1 frame cannot carry a signature:
pymavlink without ``MAVLINK20=1`` still "signs" one by appending the 13 signature bytes, which no
MAVLink 1 parser expects and no verifier can accept; such frames are counted apart
(``rx_mavlink1_signing``, "MAVLink 1 while signing is on"), their appended bytes with them, not as
bad bytes or forgeries. SETUP_SIGNING is never acted on,
forwarded or logged (it carries a key). A UDP sender is learned as a peer only from a datagram
with a valid (authenticated, when signing) frame.
"""

from __future__ import annotations

import contextlib
import logging
import select
from collections import Counter
from collections.abc import Callable
from typing import Any

from sitl.link.transports import TcpServerTransport, Transport, UdpTransport
from wire import signing
from wire.dialect import mavlink
from wire.resync import ResyncMAVLink

log = logging.getLogger(__name__)

SYSTEM_ID = 1
COMPONENT_ID = 1  # MAV_COMP_ID_AUTOPILOT1
MAVLINK1_MAGIC = 0xFE  # a MAVLink 1 frame's start byte (MAVLink 2: 0xFD)
SIGNATURE_LEN = 13  # MAVLink 2 signature: link id, 6-byte time stamp, 6-byte signature

Handler = Callable[[object, "Link"], None]


class Link:
    """One transport plus its parser state."""

    def __init__(self, transport: Transport, index: int) -> None:
        self.transport = transport
        self.index = index
        self.parser = ResyncMAVLink(None, SYSTEM_ID, COMPONENT_ID)  # re-scans a corrupt frame (wire.resync)
        #: Sender address of the datagram being parsed (UDP; None on byte streams): for replies and forwarding.
        self.rx_source: tuple[str, int] | None = None
        self.rx_valid = False  # the datagram being parsed held a valid (authenticated) frame
        #: Bytes still expected of the signature a MAVLink 1 sender appended to its last frame (0: none).
        self.v1_signature_left = 0

    @property
    def name(self) -> str:
        return self.transport.name


class Endpoint:
    """MAVLink system 1, component 1 on a set of transports."""

    def __init__(self, transports: list[Transport], signing_key: signing.SigningKey | None = None) -> None:
        self.links = [Link(t, i) for i, t in enumerate(transports)]
        self._encoder = mavlink.MAVLink(None, SYSTEM_ID, COMPONENT_ID)
        self.signing_on = signing_key is not None
        if signing_key is not None:
            signing.configure(self._encoder, signing_key, link_id=0)
            for lk in self.links:
                signing.configure(lk.parser, signing_key, link_id=0, sign_outgoing=False)
        self.handlers: dict[str, Handler] = {}
        self.counters: Counter[str] = Counter()
        self._fd_link: dict[int, Link] = {}
        self.rx_hooks: list[Callable[[object, Link], None]] = []
        # Called with every frame packed for sending (the tlog), once per frame however many links it goes to.
        self.tx_hooks: list[Callable[[bytes], None]] = []

    def signing_counts(self) -> dict[str, int]:
        """The verifiers' counts over every link (empty without signing)."""
        if not self.signing_on:
            return {}
        total: Counter[str] = Counter()
        for lk in self.links:
            total.update(signing.counts(lk.parser))
        return dict(total)

    def authentic(self, msg: object) -> bool:
        """True if ``msg`` came from a key holder (always true without signing)."""
        return signing.is_authentic(msg, self.signing_on)

    # ------------------------------------------------------------------ output
    def encode(self, msg: Any) -> bytes:
        """Pack with our identity and the next sequence number."""
        enc = self._encoder
        buf = msg.pack(enc)
        enc.seq = (enc.seq + 1) % 256
        for hook in self.tx_hooks:
            hook(buf)
        return buf

    def send(self, msg: Any, link: Link | None = None) -> None:
        """Send to one link, or to every link when ``link`` is None."""
        buf = self.encode(msg)
        targets = self.links if link is None else (link,)
        for lk in targets:
            lk.transport.write(buf)
        self.counters["tx_messages"] += 1

    def send_many(self, msgs: list, link: Link | None = None) -> None:
        if not msgs:
            return
        buf = b"".join(self.encode(m) for m in msgs)
        targets = self.links if link is None else (link,)
        for lk in targets:
            if isinstance(lk.transport, UdpTransport) and len(buf) > 1400:
                _write_chunked(lk.transport.write, buf)
            else:
                lk.transport.write(buf)
        self.counters["tx_messages"] += len(msgs)

    def reply(self, msg: Any, link: Link, to: tuple[str, int] | None = None) -> None:
        """Send an answer to the peer that asked: on ``link``, and on a UDP link only to ``to``
        (default: the sender of the datagram being handled), not to every peer of the link."""
        self.reply_many([msg], link, to)

    def reply_many(self, msgs: list, link: Link, to: tuple[str, int] | None = None) -> None:
        if not msgs:
            return
        dest = to if to is not None else link.rx_source
        t = link.transport
        if isinstance(t, UdpTransport) and dest is not None:
            buf = b"".join(self.encode(m) for m in msgs)
            _write_chunked(lambda b: t.send_to(b, dest), buf)
        elif isinstance(t, TcpServerTransport) and dest is not None:
            t.send_to(b"".join(self.encode(m) for m in msgs), int(dest[1]))
        else:
            self.send_many(msgs, link)
            return
        self.counters["tx_messages"] += len(msgs)

    # ------------------------------------------------------------------ input
    def poll(self, timeout_s: float) -> int:
        """Wait up to ``timeout_s`` for input, parse and dispatch it. Returns messages handled."""
        fds: list[int] = []
        self._fd_link.clear()
        for lk in self.links:
            for fd in lk.transport.fds():
                self._fd_link[fd] = lk
                fds.append(fd)
        if not fds:
            return 0
        try:
            ready, _, _ = select.select(fds, [], [], max(0.0, timeout_s))
        except (InterruptedError, ValueError, OSError):
            return 0
        handled = 0
        for fd in ready:
            lk = self._fd_link[fd]
            data = lk.transport.read(fd)
            if isinstance(data, list):  # datagrams
                t = lk.transport
                for dgram in data:
                    lk.rx_source = getattr(dgram, "addr", None)
                    lk.rx_valid = False
                    handled += self.feed(lk, dgram)
                    self._end_of_datagram(lk)
                    if lk.rx_valid and lk.rx_source is not None and isinstance(t, UdpTransport):
                        t.learn(lk.rx_source)
            elif data:
                # A TCP client is its own peer: answers go to it only (None for serial: one peer).
                lk.rx_source = ("tcp", fd) if isinstance(lk.transport, TcpServerTransport) else None
                handled += self.feed(lk, data)
        return handled

    def _end_of_datagram(self, lk: Link) -> None:
        p = lk.parser
        if 0 < p.buf_len() <= lk.v1_signature_left:
            pass  # a MAVLink 1 frame's appended signature that happened to start like a frame
        elif p.buf_len() > 0:
            self.counters["rx_bad"] += 1
            self.counters["rx_truncated"] += 1
        p.buf = bytearray()
        p.buf_index = 0
        p.expected_length = mavlink.HEADER_LEN_V1 + 2
        p.have_prefix_error = False
        lk.v1_signature_left = 0

    def feed(self, lk: Link, data: bytes) -> int:
        """Parse bytes that arrived on a link and dispatch the messages."""
        self.counters["rx_bytes"] += len(data)
        try:
            msgs = lk.parser.parse_buffer(data) or []
        except Exception:  # the parser must never take the endpoint down
            log.debug("parser error on %s", lk.name, exc_info=True)
            self.counters["rx_bad"] += 1
            self._end_of_datagram(lk)
            return 0
        handled = 0
        for msg in msgs:
            mtype = msg.get_type()
            if self.signing_on and self._mavlink1(lk, msg, mtype):
                continue
            if mtype == "BAD_DATA":
                reason = str(getattr(msg, "reason", ""))
                if "Invalid signature" in reason:
                    self.counters["rx_unauthenticated"] += 1  # unsigned or wrongly signed: dropped
                    continue
                self.counters["rx_bad"] += 1
                if "unknown MAVLink message ID" in reason:
                    self.counters["rx_unknown_id"] += 1
                elif "invalid MAVLink CRC" in reason:
                    self.counters["rx_bad_crc"] += 1
                continue
            if mtype.startswith("UNKNOWN_"):
                # A well-formed frame of a message this dialect does not define: not ours to act on.
                self.counters["rx_unknown_id"] += 1
                continue
            if msg.get_srcSystem() == SYSTEM_ID and msg.get_srcComponent() == COMPONENT_ID:
                continue  # our own frames reflected back (e.g. a serial loop)
            if msg.get_msgId() == signing.SETUP_SIGNING_ID:
                # It carries a key: never acted on (the key is the operator's), forwarded or logged.
                self.counters["setup_signing_ignored"] += 1
                continue
            self.counters["rx_messages"] += 1
            if self.authentic(msg):
                lk.rx_valid = True
            else:
                self.counters["rx_unsigned_allowed"] += 1
            for hook in self.rx_hooks:
                hook(msg, lk)
            handler = self.handlers.get(mtype)
            if handler is None:
                self.counters["rx_ignored"] += 1
                continue
            try:
                handler(msg, lk)
                handled += 1
            except Exception:
                log.warning("handler for %s failed", mtype, exc_info=True)
                self.counters["handler_errors"] += 1
        return handled

    def _mavlink1(self, lk: Link, msg: Any, mtype: str) -> bool:
        """With signing on: count a MAVLink 1 frame (and the signature bytes its sender appended) as
        "MAVLink 1 while signing is on"; True when ``msg`` is dropped here (an allowlisted MAVLink 1
        HEARTBEAT is counted and still handled, as PX4 accepts it unsigned)."""
        data = bytes((getattr(msg, "data", b"") if mtype == "BAD_DATA" else msg.get_msgbuf()) or b"")
        reason = str(getattr(msg, "reason", ""))
        if mtype == "BAD_DATA" and reason.startswith("Bad prefix") and 0 < len(data) <= lk.v1_signature_left:
            lk.v1_signature_left -= len(data)
            return True
        lk.v1_signature_left = 0
        if not data or data[0] != MAVLINK1_MAGIC or (mtype == "BAD_DATA" and "Invalid signature" not in reason):
            return False  # a MAVLink 2 frame, or a broken MAVLink 1 one (bad CRC: counted as bad as ever)
        self.counters["rx_mavlink1_signing"] += 1
        lk.v1_signature_left = SIGNATURE_LEN
        return mtype == "BAD_DATA"

    def close(self) -> None:
        for lk in self.links:
            with contextlib.suppress(OSError):
                lk.transport.close()


def _write_chunked(write: Callable[[bytes], None], msgs_buf: bytes) -> None:
    """UDP: keep datagrams under a typical MTU, splitting only at frame boundaries."""
    start = 0
    i = 0
    n = len(msgs_buf)
    while i < n:
        frame_len = _frame_len(msgs_buf, i)
        if i + frame_len - start > 1400 and i > start:
            write(msgs_buf[start:i])
            start = i
        i += frame_len
    if start < n:
        write(msgs_buf[start:n])


def _frame_len(buf: bytes, i: int) -> int:
    """Length of the MAVLink frame starting at ``buf[i]`` (v1 or v2, signed or not)."""
    if buf[i] == 0xFD:
        signed = buf[i + 2] & 0x01
        return 12 + buf[i + 1] + (13 if signed else 0)
    return 8 + buf[i + 1]


def targets_us(msg: Any) -> bool:
    """True if a message addressed with target_system/target_component is for us (0 = broadcast)."""
    ts = getattr(msg, "target_system", 0)
    tc = getattr(msg, "target_component", 0)
    return ts in (0, SYSTEM_ID) and tc in (0, COMPONENT_ID)
