"""The peripheral component on a UDP link to PX4's payload port (a socket standing in for it here): it
speaks as PX4's system (learned from PX4), component 158, sends ESC_STATUS / CHEM / true wind at their
rates and a non-autopilot HEARTBEAT, and scores what PX4 forwards back (WIND_COV, the declaration)."""

from __future__ import annotations

import math
import socket
import time
from collections import Counter

import numpy as np
import pytest
from hil_support import ARMED, FakePx4, Policy, bridge, hover_output, outputs_const, place_in_air, serving, wait_for

from sitl.hil.peripheral import UdpPeripheral
from wire.dialect import mavlink
from wire.names import declaration_messages


def test_peripheral_talks_as_px4s_component_158_and_scores_what_comes_back() -> None:
    payload = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # PX4's payload link
    payload.bind(("127.0.0.1", 0))
    payload.settimeout(0.05)
    b, said = bridge()
    place_in_air(b, 5.0)
    periph = UdpPeripheral(("127.0.0.1", payload.getsockname()[1]), system_id=1)
    rx = mavlink.MAVLink(None, 0, 0)
    rx.robust_parsing = True
    kinds: Counter[str] = Counter()
    sources: set[tuple[int, int]] = set()
    heartbeats = []
    peer = None
    est = mavlink.MAVLink(None, 7, 191)  # the estimator's identity, as PX4 forwards it
    with serving(b, said, peripheral=periph) as runner:
        px4 = FakePx4(runner.link.port, sysid=7, policy=Policy(outputs=outputs_const([hover_output(b)] * 4),
                                                                 mode=ARMED))  # fmt: skip
        end = time.monotonic() + 30.0
        while b.world.t < 2.0 and time.monotonic() < end:
            try:
                data, peer = payload.recvfrom(65536)
            except TimeoutError:
                continue
            for m in rx.parse_buffer(data) or []:
                sources.add((m.get_srcSystem(), m.get_srcComponent()))
                kinds[m.name if m.get_type() == "NAMED_VALUE_FLOAT" else m.get_type()] += 1
                if m.get_type() == "HEARTBEAT":
                    heartbeats.append(m)
        t_sent = b.world.t
        assert peer is not None
        # What PX4 would forward from the companions: 3 wind estimates (still air: the truth is 0) and a declaration.
        for k in range(3):
            t_us = int((t_sent - 0.2 - 0.1 * k) * 1e6)
            msg = mavlink.MAVLink_wind_cov_message(t_us, 1.0, -0.5, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0)
            payload.sendto(msg.pack(est), peer)
        for m in declaration_messages(t_sent, [18.0, 1.0, -2.0], 0.9):
            payload.sendto(m.pack(est), peer)
        payload.sendto(b"\xfd\x09garbage", peer)  # malformed: counted, dropped
        # (the garbage is read after the scores: wait for it too, or its count races the summary)
        sc = b.truth
        wait_for(lambda: sc.estimator.n == 3 and sc.declaration is not None and periph.counters["rx_bad"] >= 1,
                 what="the scores and the malformed datagram counted")  # fmt: skip
        t_end = b.world.t
        px4.close()
    payload.close()
    assert sources == {(7, 158)}  # PX4's system id, learned from PX4; never the default 1
    assert heartbeats and all(h.autopilot == mavlink.MAV_AUTOPILOT_INVALID and h.type == mavlink.MAV_TYPE_GENERIC
                              for h in heartbeats)  # fmt: skip
    sim_s = t_sent  # messages collected until then
    assert kinds["ESC_STATUS"] == pytest.approx(50 * sim_s, rel=0.1)
    assert kinds["CHEM"] == pytest.approx(10 * sim_s, rel=0.15)
    assert kinds["TRUEWN"] == pytest.approx(5 * sim_s, rel=0.25)
    d = runner.summary()
    assert d["wind_estimates_scored"] == 3
    assert d["wind_rmse_ned_m_s"] == pytest.approx([1.0, 0.5, 0.0], abs=1e-6)
    assert d["declared_error_horizontal_m"] == pytest.approx(math.hypot(2.0, 1.0), abs=1e-3)
    assert d["peripheral_rx_bad"] >= 1
    assert t_end >= t_sent and np.isfinite(d["sim_time_s"])
