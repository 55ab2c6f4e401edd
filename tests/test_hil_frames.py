"""The lockstep link's own framing (sitl/hil/frames.py): every frame windseek sends is byte for byte what
pymavlink packs, PX4's answers decode to what pymavlink decodes, and anything else (other messages,
garbage, a bad CRC, a split frame) still goes through pymavlink's robust parser over a real socket."""

from __future__ import annotations

import socket
from typing import Any

import numpy as np
import pytest
from hil_support import hover_output, place_in_air, scenario

from sitl.hil import messages as hm
from sitl.hil.bridge import HilBridge
from sitl.hil.frames import FrameEncoder, crc16, split_controls
from sitl.hil.px4_link import SimLink
from wire.dialect import mavlink
from wire.dialect.windseek import x25crc


def _pymavlink_frames(msgs: list, sysid: int, compid: int) -> list[bytes]:
    enc = mavlink.MAVLink(None, sysid, compid)
    out = []
    for m in msgs:
        out.append(m.pack(enc))
        enc.seq = (enc.seq + 1) % 256
    return out


def _as_pymavlink(m: Any) -> Any:
    """pymavlink's message of the same fields as one of windseek's wire-order tuples (others unchanged)."""
    if isinstance(m, hm.HilSensor):
        return mavlink.MAVLink_hil_sensor_message(*m)
    if isinstance(m, hm.HilStateQuaternion):
        v: list[Any] = list(m)
        return mavlink.MAVLink_hil_state_quaternion_message(v[0], v[1:5], *v[5:])
    return m


def test_crc16_is_mavlinks_crc() -> None:
    rng = np.random.default_rng(7)
    for n in (0, 1, 2, 17, 80, 279):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert crc16(data) == x25crc(data).crc


def test_frames_equal_pymavlink_for_everything_the_bridge_and_peripheral_send() -> None:
    b = HilBridge(scenario(), say=lambda s: None)
    place_in_air(b, 5.0)
    b.on_controls([hover_output(b)] * 4 + [0.0] * 12, 128)
    msgs: list = []
    for _ in range(300):  # 1.2 s: HIL_SENSOR with and without mag/baro, HIL_GPS, HIL_STATE_QUATERNION, ESC, CHEM, wind
        out = b.step()
        msgs += out.to_px4 + out.to_companion
    msgs += [hm.heartbeat_peripheral(), hm.named_value(1.0, "CHEM", 0.0), hm.esc_status(0.5, np.zeros(4))]
    kinds = {m.get_type() for m in msgs}
    assert {"HIL_SENSOR", "HIL_GPS", "HIL_STATE_QUATERNION", "ESC_STATUS", "NAMED_VALUE_FLOAT", "HEARTBEAT"} <= kinds
    enc = FrameEncoder(7, 158)
    mine = [enc.encode(m) for m in msgs]
    # HIL_SENSOR and HIL_STATE_QUATERNION are wire-order tuples: pymavlink's message of the same fields packs the same.
    assert any(isinstance(m, hm.HilSensor) for m in msgs)
    assert any(isinstance(m, hm.HilStateQuaternion) for m in msgs)
    ref: list[Any] = [_as_pymavlink(m) for m in msgs]
    assert mine == _pymavlink_frames(ref, 7, 158)
    assert enc.seq == len(msgs) % 256
    # Decoded by pymavlink's parser: the same messages.
    p = mavlink.MAVLink(None, 0, 0)
    back: Any = p.parse_buffer(b"".join(mine))
    assert [m.get_type() for m in back] == [m.get_type() for m in msgs]


def _controls_frame(controls: list[float], mode: int, t_us: int, seq: int = 0, sysid: int = 1) -> bytes:
    enc = mavlink.MAVLink(None, sysid, 1)
    enc.seq = seq
    return mavlink.MAVLink_hil_actuator_controls_message(t_us, controls, mode, 1).pack(enc)


def test_split_controls_decodes_what_pymavlink_decodes() -> None:
    armed = _controls_frame([0.61, 0.62, 0.63, 0.64] + [0.0] * 12, 129, 123_456_000, seq=9, sysid=3)
    disarmed = _controls_frame([0.0] * 16, 0, 4000)  # MAVLink 2 truncates this payload to its first bytes
    assert len(disarmed) < len(armed)
    msgs, rest = split_controls(armed + disarmed)
    assert rest == b""
    ref: Any = mavlink.MAVLink(None, 0, 0).parse_buffer(armed + disarmed)
    assert len(msgs) == len(ref) == 2
    for m, r in zip(msgs, ref, strict=True):
        assert m.get_type() == "HIL_ACTUATOR_CONTROLS"
        assert (m.time_usec, m.mode, m.flags) == (r.time_usec, r.mode, r.flags)
        assert list(m.controls) == pytest.approx(list(r.controls))
        assert (m.get_srcSystem(), m.get_srcComponent(), m.get_seq()) == (r.get_srcSystem(), r.get_srcComponent(),
                                                                          r.get_seq())  # fmt: skip
        assert bytes(m.get_msgbuf()) == bytes(r.get_msgbuf())


def test_split_controls_leaves_other_messages_bad_crc_and_partial_frames_to_the_parser() -> None:
    ok = _controls_frame([0.5] * 4 + [0.0] * 12, 129, 8000)
    hb = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(mavlink.MAVLink(None, 1, 1))
    bad = bytearray(ok)
    bad[20] ^= 0xFF
    for tail in (hb, bytes(bad), ok[:30], b"\x00garbage"):
        msgs, rest = split_controls(ok + tail)
        assert len(msgs) == 1 and rest == tail


def _pair() -> tuple[SimLink, socket.socket]:
    """A SimLink reading one end of a real socket pair."""
    a, b = socket.socketpair()

    class Link(SimLink):
        connected = True

        def fileno(self) -> int | None:
            return a.fileno()

        def _read(self) -> bytes:
            return a.recv(65536)

        def close(self) -> None:
            a.close()

    return Link(1, 158), b


def test_receive_mixed_stream_split_frames_and_garbage() -> None:
    link, peer = _pair()
    try:
        f1 = _controls_frame([0.5] * 4 + [0.0] * 12, 129, 4000)
        f2 = _controls_frame([0.6] * 4 + [0.0] * 12, 129, 8000)
        hb = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(mavlink.MAVLink(None, 1, 1))
        got: list = []
        for chunk in (f1 + hb + f2[:40], f2[40:]):
            peer.sendall(chunk)
            got += link.receive(1.0)
        assert [m.get_type() for m in got] == ["HIL_ACTUATOR_CONTROLS", "HEARTBEAT", "HIL_ACTUATOR_CONTROLS"]
        assert [m.time_usec for m in got if m.get_type() != "HEARTBEAT"] == [4000, 8000]
        # Garbage that looks like a frame start swallows what follows until the parser resynchronizes (as
        # pymavlink alone does); it is counted, and the answers after it arrive.
        peer.sendall(b"\xfd\x05garbage!!" + f1)
        after: list = []
        for _ in range(6):
            after += link.receive(0.2)
            peer.sendall(f2)
        assert link.counters["rx_bad"] >= 1
        assert [m.time_usec for m in after][-3:] == [8000, 8000, 8000]
        assert all(m.get_type() == "HIL_ACTUATOR_CONTROLS" for m in after)
    finally:
        link.close()
        peer.close()


def test_signed_answers_are_left_to_pymavlinks_parser() -> None:
    """The fast path takes unsigned frames only (PX4's simulator link does not sign); a signed frame goes to
    pymavlink's parser, which checks its signature, and decodes to the same values."""
    enc = mavlink.MAVLink(None, 1, 1)
    enc.signing.secret_key = bytes(range(32))
    enc.signing.link_id = 2
    enc.signing.sign_outgoing = True
    signed = mavlink.MAVLink_hil_actuator_controls_message(4000, [0.5] * 4 + [0.0] * 12, 129, 1).pack(enc)
    assert signed[2] & mavlink.MAVLINK_IFLAG_SIGNED
    msgs, rest = split_controls(signed)
    assert msgs == [] and rest == signed
    link, peer = _pair()
    try:
        link._parser.signing.secret_key = bytes(range(32))
        peer.sendall(signed)
        got = link.receive(1.0)
        assert [(m.get_type(), m.time_usec, m.mode) for m in got] == [("HIL_ACTUATOR_CONTROLS", 4000, 129)]
    finally:
        link.close()
        peer.close()
