"""MAVLink 2 frames for the lockstep link, packed and unpacked with precompiled structs.

The lockstep loop is serial (windseek steps, PX4 steps, windseek steps ...), so every microsecond
windseek spends per 4 ms step is lost from the lockstep speed. pymavlink's generic ``pack`` builds a
header object, a bytearray and several temporaries per message, and its parser walks the input
through Python-level state per frame; together about a quarter of windseek's work per step. This
module does the same with one ``struct`` call and a C-level CRC per frame:

- :class:`FrameEncoder` packs any message object of the project dialect (unsigned MAVLink 2,
  payload truncated as MAVLink 2 requires), byte for byte what ``message.pack(mav)`` produces
  (a test checks it for every message the HIL link and the peripheral send);
- :func:`split_controls` takes the HIL_ACTUATOR_CONTROLS frames PX4 answers each step off the
  front of the received bytes, checks their CRC and decodes them into :class:`Controls` tuples;
  everything else (and anything that does not check out) goes to pymavlink's robust parser, unchanged.

The CRC is MAVLink's CRC-16/MCRF4XX (the reflected CCITT polynomial, init 0xFFFF). The standard
library's ``binascii.crc_hqx`` computes the non-reflected CCITT CRC in C; a reflected CRC is the
bit reversal of the non-reflected CRC of the bit-reversed bytes (same init, 0xFFFF being its own
reversal), so ``crc = rev16(crc_hqx(data.translate(REV8), 0xFFFF))``.
"""

from __future__ import annotations

import binascii
import re
import struct
from collections.abc import Callable
from typing import Any, NamedTuple

from wire.dialect import mavlink

#: Bit reversal of every byte value (a translation table for bytes.translate).
_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))
_HDR = struct.Struct("<BBBBBBBHB")  # magic, len, incompat, compat, seq, sys, comp, msgid low 16, msgid high 8
_CRC = struct.Struct("<H")
MAGIC_V2 = 0xFD
HEADER_LEN = 10
MSG_ID_HIL_ACTUATOR_CONTROLS = mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS
_CONTROLS = mavlink.MAVLink_hil_actuator_controls_message
_CONTROLS_LEN = _CONTROLS.unpacker.size  # 81: time_usec, flags, controls[16], mode
_CONTROLS_UNPACK = _CONTROLS.unpacker.unpack_from


def crc16(data: bytes) -> int:
    """MAVLink's CRC-16/MCRF4XX of ``data`` (see the module docstring)."""
    c = binascii.crc_hqx(data.translate(_REV8), 0xFFFF)
    return (_REV8[c & 0xFF] << 8) | _REV8[c >> 8]


def _payload_packer(cls: Any) -> Callable[[Any], bytes]:
    """A function packing the payload of a message of class ``cls`` (fields in wire order)."""
    tokens = re.findall(r"(\d*)([a-zA-Z?])", cls.unpacker.format)
    names = list(cls.ordered_fieldnames)
    if len(tokens) != len(names):  # pragma: no cover - the generator writes one token per field
        raise ValueError(f"{cls.msgname}: format {cls.unpacker.format} does not match its fields")
    spread = [bool(n) and code != "s" for n, code in tokens]  # numeric arrays: one struct item per element
    text = [code == "s" for _, code in tokens]
    pack = cls.unpacker.pack

    def payload(m: Any) -> bytes:
        vals: list[Any] = []
        for name, sp, tx in zip(names, spread, text, strict=True):
            v = getattr(m, name)
            if sp:
                vals.extend(v)
            elif tx and isinstance(v, str):
                vals.append(v.encode())
            else:
                vals.append(v)
        return pack(*vals)

    return payload


def _plan(cls: Any) -> tuple[int, int, Callable[[Any], bytes]]:
    """Message id, CRC extra and payload packer of a message class: a pymavlink class, or a tuple type
    in wire order with ``WIRE = (id, crc_extra, struct)`` (:class:`sitl.hil.messages.HilSensor`)."""
    wire = getattr(cls, "WIRE", None)
    if wire is not None:
        pack = wire[2].pack
        return int(wire[0]), int(wire[1]), lambda m: pack(*m)
    return int(cls.id), int(cls.crc_extra), _payload_packer(cls)


class FrameEncoder:
    """Unsigned MAVLink 2 frames from ``system_id``/``component_id`` with a running sequence number.

    ``system_id`` and ``component_id`` may be changed between frames (the HIL link adopts PX4's id).
    """

    def __init__(self, system_id: int, component_id: int) -> None:
        self.srcSystem = int(system_id)  # pymavlink's attribute names: code that sets them keeps working
        self.srcComponent = int(component_id)
        self.seq = 0
        self._plans: dict[type, tuple[int, int, Callable[[Any], bytes]]] = {}

    def frame(self, msgid: int, crc_extra: int, payload: bytes) -> bytes:
        """One frame of a packed payload (trailing zero bytes dropped, at least one kept)."""
        p = payload.rstrip(b"\0") or payload[:1]
        head = _HDR.pack(MAGIC_V2, len(p), 0, 0, self.seq, self.srcSystem, self.srcComponent, msgid & 0xFFFF,
                         msgid >> 16)  # fmt: skip
        self.seq = (self.seq + 1) & 0xFF
        body = head + p
        return body + _CRC.pack(crc16(body[1:] + bytes((crc_extra,))))

    def encode(self, m: Any) -> bytes:
        """The frame of a message ``m`` (a pymavlink message object, or a wire-order tuple: see :func:`_plan`)."""
        cls = type(m)
        plan = self._plans.get(cls)
        if plan is None:
            plan = self._plans[cls] = _plan(cls)
        return self.frame(plan[0], plan[1], plan[2](m))


class Controls(NamedTuple):
    """One decoded HIL_ACTUATOR_CONTROLS: pymavlink's field names and units (``controls``: 16 outputs,
    ``mode``: MAV_MODE_FLAG bits, ``flags``: bit 0 = lockstep), its sender and its frame's bytes.

    A tuple rather than pymavlink's message object: building that object (a header object, several
    buffers, a dozen attribute writes) was a good part of windseek's work per lockstep step. The
    ``get_*`` methods are pymavlink's, so code that handles messages reads it the same way."""

    time_usec: int
    controls: tuple[float, ...]
    mode: int
    flags: int
    src_system: int
    src_component: int
    seq: int
    frame: bytes

    def get_type(self) -> str:
        return "HIL_ACTUATOR_CONTROLS"

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        return self.src_system

    def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
        return self.src_component

    def get_seq(self) -> int:
        return self.seq

    def get_msgbuf(self) -> bytes:
        return self.frame


def _controls(buf: bytes, start: int, plen: int) -> Controls:
    """The HIL_ACTUATOR_CONTROLS of a checked frame at ``buf[start:]`` (payload ``plen`` bytes)."""
    frame = buf[start : start + HEADER_LEN + plen + 2]
    if plen == _CONTROLS_LEN:
        v = _CONTROLS_UNPACK(frame, HEADER_LEN)
    else:  # MAVLink 2 truncates trailing zeros
        v = _CONTROLS_UNPACK(frame[HEADER_LEN : HEADER_LEN + plen] + bytes(_CONTROLS_LEN - plen))
    return Controls(v[0], v[2:18], v[18], v[1], frame[5], frame[6], frame[4], frame)


def split_controls(buf: bytes) -> tuple[list[Controls], bytes]:
    """HIL_ACTUATOR_CONTROLS frames at the front of ``buf``, decoded, and the bytes after them.

    Only whole, unsigned MAVLink 2 frames of that message whose CRC checks are taken; the first
    byte that is anything else ends the scan and the rest is returned for the generic parser
    (which counts what is bad). The caller feeds only data that starts at a frame boundary.
    """
    out: list[Controls] = []
    i, n = 0, len(buf)
    while n - i >= HEADER_LEN + 2 and buf[i] == MAGIC_V2 and buf[i + 2] == 0:  # incompat flags 0: unsigned
        plen = buf[i + 1]
        end = i + HEADER_LEN + plen + 2
        msgid = buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16
        if msgid != MSG_ID_HIL_ACTUATOR_CONTROLS or plen > _CONTROLS_LEN or end > n:
            break
        crc = _CRC.unpack_from(buf, end - 2)[0]
        if crc != crc16(buf[i + 1 : end - 2] + bytes((_CONTROLS.crc_extra,))):
            break
        out.append(_controls(buf, i, plen))
        i = end
    return out, buf[i:]
