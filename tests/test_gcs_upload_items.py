"""The ground station's mission upload (sitl/ardupilot/gcs.py ``upload_items``, used for ArduCopter and PX4)
against a scripted autopilot: every requested item sent once as MISSION_ITEM_INT, a navigation command in
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT and a DO_ command in MAV_FRAME_MISSION (PX4 refuses a DO_CHANGE_SPEED in a
global frame), a request out of range ignored, the MISSION_ACK's type returned, None when the autopilot is silent."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from sitl.ardupilot.gcs import upload_items
from wire.dialect import mavlink as M  # noqa: N812

ITEMS = [(M.MAV_CMD_DO_CHANGE_SPEED, 0.0, 0.0, 0.0, 1.0, 3.0), (M.MAV_CMD_NAV_WAYPOINT, 47.3977, 8.5456, 10.0, 5.0)]


class _Autopilot:
    """Requests the items in order (with a stray request for a seq it never announced first), then ACKs."""

    def __init__(self, requests: list[int], ack: int | None) -> None:
        self.answers: list[Any] = [SimpleNamespace(get_type=lambda: "MISSION_REQUEST_INT", seq=s) for s in requests]
        if ack is not None:
            self.answers.append(SimpleNamespace(get_type=lambda: "MISSION_ACK", type=ack))
        self.sent: list[tuple[str, tuple[Any, ...]]] = []

    def send(self, fn: str, *args: Any) -> None:
        self.sent.append((fn, args))

    def wait(self, types: list[str], timeout_s: float) -> Any:
        return self.answers.pop(0) if self.answers else None


def test_upload_items_sends_each_requested_item_in_its_frame() -> None:
    ap = _Autopilot([7, 0, 1], M.MAV_MISSION_ACCEPTED)
    assert upload_items(ap.send, ap.wait, 42, ITEMS) == M.MAV_MISSION_ACCEPTED
    assert ap.sent[0] == ("mission_count_send", (42, 1, 2, 0))
    items = [a for fn, a in ap.sent if fn == "mission_item_int_send"]
    assert [a[2] for a in items] == [0, 1]  # seq 7 (never announced) is not answered
    speed, wp = items
    assert speed[3] == M.MAV_FRAME_MISSION and speed[4] == M.MAV_CMD_DO_CHANGE_SPEED and speed[7:9] == (1.0, 3.0)
    assert wp[3] == M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT and wp[4] == M.MAV_CMD_NAV_WAYPOINT
    assert wp[7] == 5.0 and wp[11:14] == (473977000, 85456000, 10.0)  # hold s; lat, lon 1e7; alt m


def test_upload_items_returns_a_refusal_or_none() -> None:
    ap = _Autopilot([0], M.MAV_MISSION_UNSUPPORTED)
    assert upload_items(ap.send, ap.wait, 1, ITEMS) == M.MAV_MISSION_UNSUPPORTED
    silent = _Autopilot([0], None)
    assert upload_items(silent.send, silent.wait, 1, ITEMS) is None
