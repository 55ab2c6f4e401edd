"""Every refused mission-protocol request is explained (issue 31, finding 5): a STATUSTEXT (severity
CRITICAL, as PX4's mission manager sends its "IGN MISSION_ITEM: No transfer" and the like) comes with
each MISSION_ACK that is not ACCEPTED. A pymavlink ground station on a real UDP socket makes each kind of
refusal, including dronekit's guided goto (a MISSION_ITEM with current = 2), which used to get a bare
MISSION_ACK DENIED.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

from link_support import free_port, quiet_running, wait_until
from pymavlink import mavutil

from wire.dialect import mavlink as M  # noqa: N812


def _answer(gcs: Any) -> tuple[list[Any], Any]:
    """The STATUSTEXTs received before the next MISSION_ACK, and that ACK."""
    texts: list[Any] = []
    t_end = time.monotonic() + 5.0
    while time.monotonic() < t_end:
        m = gcs.recv_match(type=["STATUSTEXT", "MISSION_ACK"], blocking=True, timeout=1)
        if m is None or m.get_srcSystem() != 1:
            continue
        if m.get_type() == "MISSION_ACK":
            return texts, m
        texts.append(m)
    raise AssertionError("no MISSION_ACK within 5 s")


def test_every_mission_refusal_comes_with_a_statustext() -> None:
    port = free_port()
    with quiet_running(port) as link:
        os.environ["MAVLINK20"] = "1"
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
        assert gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
        wait_until(lambda: link.sim.t > 0.3, 5.0, "the SITL streaming")
        item = M.MAVLink_mission_item_message
        wp, rel = M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT
        refusals = {
            "Goto (current=2) unsupported, use DO_REPOSITION":  # dronekit's simple_goto, as it sends it
                lambda: gcs.mav.send(item(1, 1, 0, rel, wp, 2, 0, 0, 0, 0, 0, 47.39, 8.54, 3.0)),
            "IGN MISSION_ITEM: No transfer": lambda: gcs.mav.send(item(1, 1, 0, rel, wp, 0, 1, 0, 0, 0, 0, 47.39,
                                                                       8.54, 3.0)),  # fmt: skip
            "Mission type 2 not supported": lambda: gcs.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_RALLY),
            "Mission too large: 5000 > 1000": lambda: gcs.mav.mission_count_send(1, 1, 5000, 0),
            "Requested item 3 out of bounds (0)": lambda: gcs.mav.mission_request_int_send(1, 1, 3, 0),
        }
        for why, send in refusals.items():
            send()
            texts, ack = _answer(gcs)
            assert ack.type != M.MAV_MISSION_ACCEPTED, why
            assert [(t.severity, t.text) for t in texts] == [(M.MAV_SEVERITY_CRITICAL, why)], (why, texts)
        # A bad item in an upload: the reason names the item and what is wrong with it.
        gcs.mav.mission_count_send(1, 1, 1, 0)
        assert gcs.recv_match(type="MISSION_REQUEST_INT", blocking=True, timeout=3).seq == 0
        gcs.mav.send(M.MAVLink_mission_item_int_message(1, 1, 0, 6, wp, 0, 1, 0, 0, 0, math.nan, 473_977_000,
                                                        85_456_000, math.nan, 0))  # fmt: skip
        texts, ack = _answer(gcs)
        assert ack.type == M.MAV_MISSION_INVALID_PARAM7
        assert len(texts) == 1 and texts[0].text.startswith("Mission item 0 rejected: "), texts
        # An accepted request gets no STATUSTEXT.
        gcs.mav.mission_clear_all_send(1, 1, 0)
        texts, ack = _answer(gcs)
        assert ack.type == M.MAV_MISSION_ACCEPTED and texts == []
