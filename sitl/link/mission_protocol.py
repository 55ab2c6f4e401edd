"""MAVLink mission protocol for missions (type 0) and the geofence (type 1); rally unsupported.

Upload: MISSION_COUNT -> MISSION_REQUEST_INT(seq) ... -> MISSION_ACK, with the request
re-sent after ``REQUEST_TIMEOUT_S`` (wall clock) up to ``REQUEST_RETRIES`` times, then the
transfer is abandoned with MAV_MISSION_OPERATION_CANCELLED. Download: MISSION_REQUEST_LIST
-> MISSION_COUNT, MISSION_REQUEST_INT(seq) -> MISSION_ITEM_INT. Clear: MISSION_CLEAR_ALL.
Set current: MISSION_SET_CURRENT. A rejected upload leaves the previous plan in place.

Mission items: NAV_WAYPOINT (param1 hold s, param2 acceptance radius m, param4 yaw deg),
NAV_TAKEOFF (z), NAV_LAND (x, y or 0/0 = here), NAV_LOITER_TIME (param1 s), NAV_RETURN_TO_LAUNCH,
DO_CHANGE_SPEED (param2 m/s), NAV_DELAY (param1 s, waits where the vehicle is), DO_LAND_START
(a marker, as on PX4: the command DO_LAND_START continues the mission from it).
Frames GLOBAL(_INT) (AMSL) and GLOBAL_RELATIVE_ALT(_INT)
(above home); DO items also MISSION. Geofence items: NAV_FENCE_POLYGON_VERTEX_INCLUSION /
EXCLUSION (param1 vertex count), NAV_FENCE_CIRCLE_INCLUSION / EXCLUSION (param1 radius m),
NAV_FENCE_RETURN_POINT (stored, not used). Errors use the MAV_MISSION_RESULT codes, and every
MISSION_ACK that is not ACCEPTED follows a STATUSTEXT (severity CRITICAL) saying why, as PX4's mission
manager does ("IGN MISSION_ITEM: No transfer", ...). A guided goto (a MISSION_ITEM with current = 2,
dronekit's ``simple_goto``) is ArduPilot's; PX4 answers it as an item without a transfer, and so
does this link, naming MAV_CMD_DO_REPOSITION, PX4's way to fly to a point.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sitl.autopilot.flight_modes import ItemKind, MissionItem, Mode
from sitl.link.endpoint import Endpoint, Link, targets_us
from sitl.link.geofence import Geofence
from sitl.link.port import AutopilotPort
from sitl.world.sensors import geodetic_to_ned
from wire.dialect import mavlink as mav

REQUEST_TIMEOUT_S = 0.5
REQUEST_RETRIES = 5
MAX_ITEMS = 1000

MISSION = mav.MAV_MISSION_TYPE_MISSION
FENCE = mav.MAV_MISSION_TYPE_FENCE

GLOBAL_FRAMES = {mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT}
RELATIVE_FRAMES = {mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
POSITION_FRAMES = GLOBAL_FRAMES | RELATIVE_FRAMES

NAV_KINDS = {
    mav.MAV_CMD_NAV_WAYPOINT: ItemKind.WAYPOINT,
    mav.MAV_CMD_NAV_TAKEOFF: ItemKind.TAKEOFF,
    mav.MAV_CMD_NAV_LAND: ItemKind.LAND,
    mav.MAV_CMD_NAV_LOITER_TIME: ItemKind.LOITER_TIME,
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: ItemKind.RTL,
    mav.MAV_CMD_DO_CHANGE_SPEED: ItemKind.CHANGE_SPEED,
    mav.MAV_CMD_NAV_DELAY: ItemKind.LOITER_TIME,  # MAVSDK's loiter_time_s: wait where the vehicle is
}
MAV_CMD_DO_LAND_START = 189
FENCE_CMDS = {
    mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
    mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
    mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
    mav.MAV_CMD_NAV_FENCE_RETURN_POINT,
}


class ItemError(ValueError):
    """A mission item the vehicle refuses; ``code`` is the MAV_MISSION_RESULT."""

    def __init__(self, code: int, text: str) -> None:
        super().__init__(text)
        self.code = code


@dataclass
class Transfer:
    link: Link
    addr: tuple[str, int] | None  # the uploader's UDP address (None on byte streams): re-requests go there
    mission_type: int
    count: int
    sysid: int
    compid: int
    items: list = field(default_factory=list)
    next_seq: int = 0
    deadline: float = 0.0
    retries: int = 0


class MissionProtocol:
    """Mission/geofence storage and transfers of the built-in autopilot (:class:`AutopilotPort`)."""

    def __init__(self, ep: Endpoint, ap: AutopilotPort, geofence: Geofence,
                 mission_current: Callable[[], list[Any]]) -> None:  # fmt: skip
        self.ep = ep
        self.ap = ap
        self.geofence = geofence
        self.mission_current = mission_current
        self.plans: dict[int, list] = {MISSION: [], FENCE: []}  # the raw MISSION_ITEM_INT messages
        self.transfer: Transfer | None = None
        # (link index, sender address, type, count) of the last upload, to re-ACK a lost final ACK.
        self._last_done: tuple[int, Any, int, int] | None = None
        for name in ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_REQUEST_LIST",
                     "MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT",
                     "MISSION_ACK"):  # fmt: skip
            self.ep.handlers[name] = getattr(self, "on_" + name.lower())

    # ------------------------------------------------------------------ helpers
    def _ack(self, link: Link, msg: Any, code: int, mission_type: int, why: str = "") -> None:
        """MISSION_ACK ``code`` to the sender; a refusal comes after a STATUSTEXT with ``why`` (<= 50 chars)."""
        if code != mav.MAV_MISSION_ACCEPTED:
            text = why or f"Mission refused: result {code}"
            self.ep.reply(mav.MAVLink_statustext_message(mav.MAV_SEVERITY_CRITICAL, text.encode()[:50]), link)
        self.ep.reply(
            mav.MAVLink_mission_ack_message(msg.get_srcSystem(), msg.get_srcComponent(), code, mission_type), link
        )
        if code != mav.MAV_MISSION_ACCEPTED:
            self.ep.counters["mission_errors"] += 1

    def _request(self, tr: Transfer) -> None:
        self.ep.reply(
            mav.MAVLink_mission_request_int_message(tr.sysid, tr.compid, tr.next_seq, tr.mission_type), tr.link,
            tr.addr,
        )
        tr.deadline = time.monotonic() + REQUEST_TIMEOUT_S

    def tick(self) -> None:
        """Re-request after a timeout; give up after the retries (called by the runner loop)."""
        tr = self.transfer
        if tr is None or time.monotonic() < tr.deadline:
            return
        if tr.retries >= REQUEST_RETRIES:
            self.ep.reply_many([
                mav.MAVLink_statustext_message(mav.MAV_SEVERITY_CRITICAL, b"Operation timeout"),  # PX4's words
                mav.MAVLink_mission_ack_message(tr.sysid, tr.compid, mav.MAV_MISSION_OPERATION_CANCELLED,
                                              tr.mission_type)], tr.link, tr.addr)  # fmt: skip
            self.ep.counters["mission_timeouts"] += 1
            self.transfer = None
            return
        tr.retries += 1
        self._request(tr)

    # ------------------------------------------------------------------ upload
    def on_mission_count(self, msg: Any, link: Link) -> None:
        if not targets_us(msg):
            return
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype not in (MISSION, FENCE):
            self._ack(link, msg, mav.MAV_MISSION_UNSUPPORTED, mtype, f"Mission type {mtype} not supported")
            return
        if msg.count > MAX_ITEMS:
            self._ack(link, msg, mav.MAV_MISSION_NO_SPACE, mtype, f"Mission too large: {msg.count} > {MAX_ITEMS}")
            return
        if msg.count == 0:
            self._install(mtype, [])
            self._ack(link, msg, mav.MAV_MISSION_ACCEPTED, mtype)
            return
        # A new MISSION_COUNT restarts any transfer in progress (a retried count is a restart too).
        self.transfer = Transfer(link, link.rx_source, mtype, msg.count, msg.get_srcSystem(), msg.get_srcComponent())
        self._request(self.transfer)

    def on_mission_item(self, msg: Any, link: Link) -> None:
        # Legacy float item: same fields, lat/lon in degrees.
        self._on_item(msg, link, as_int=False)

    def on_mission_item_int(self, msg: Any, link: Link) -> None:
        self._on_item(msg, link, as_int=True)

    def _on_item(self, msg: Any, link: Link, as_int: bool) -> None:
        if not targets_us(msg):
            return
        mtype = getattr(msg, "mission_type", MISSION)
        tr = self.transfer
        if tr is None or tr.link is not link or tr.addr != link.rx_source or tr.mission_type != mtype:
            if self._last_done == (link.index, link.rx_source, mtype, msg.seq + 1):
                self._ack(link, msg, mav.MAV_MISSION_ACCEPTED, mtype)  # our final ACK was lost
            elif getattr(msg, "current", 0) == 2:  # ArduPilot's guided goto: PX4 has no such item
                self._ack(link, msg, mav.MAV_MISSION_DENIED, mtype, "Goto (current=2) unsupported, use DO_REPOSITION")
            else:
                self._ack(link, msg, mav.MAV_MISSION_DENIED, mtype, "IGN MISSION_ITEM: No transfer")
            return
        if msg.seq < tr.next_seq:
            # A duplicate (the link doubled it, or the sender resent it): ignored, as PX4 does. Asking
            # again here would answer every duplicate with a request, and those with more duplicates:
            # MAVSDK counts each repeated request as a retry and gives up (seen through wire.proxy).
            self.ep.counters["mission_duplicates"] += 1
            return
        if msg.seq > tr.next_seq:
            self._ack(link, msg, mav.MAV_MISSION_INVALID_SEQUENCE, mtype,
                      f"Unexpected waypoint index {msg.seq}, aborting")  # fmt: skip
            self.transfer = None
            return
        item = _normalise(msg, as_int)
        try:
            self._validate(item, mtype)
        except ItemError as e:
            self._ack(link, msg, e.code, mtype, f"Mission item {msg.seq} rejected: {e}")
            self.transfer = None
            return
        tr.items.append(item)
        tr.next_seq += 1
        tr.retries = 0
        if tr.next_seq < tr.count:
            self._request(tr)
            return
        try:
            self._install(mtype, tr.items)
        except ItemError as e:
            self._ack(link, msg, e.code, mtype, f"Mission rejected: {e}")
            self.transfer = None
            return
        self.transfer = None
        self._last_done = (link.index, link.rx_source, mtype, tr.count)
        self._ack(link, msg, mav.MAV_MISSION_ACCEPTED, mtype)

    def _validate(self, it: dict, mtype: int) -> None:
        cmd, frame = it["command"], it["frame"]
        if mtype == FENCE:
            if cmd not in FENCE_CMDS:
                raise ItemError(mav.MAV_MISSION_UNSUPPORTED, f"command {cmd} is not a fence item")
            if frame not in POSITION_FRAMES:
                raise ItemError(mav.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {frame}")
            _check_latlon(it)
            if cmd in (mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION):
                if not (math.isfinite(it["param1"]) and it["param1"] > 0):
                    raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, "circle radius must be > 0")
            elif cmd != mav.MAV_CMD_NAV_FENCE_RETURN_POINT and not (math.isfinite(it["param1"]) and it["param1"] >= 3):
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, "polygon needs >= 3 vertices")
            return
        if cmd == MAV_CMD_DO_LAND_START:
            return  # a marker; its position fields are informative only (PX4 ignores them too)
        kind = NAV_KINDS.get(cmd)
        if kind is None:
            raise ItemError(mav.MAV_MISSION_UNSUPPORTED, f"command {cmd} not supported")
        if kind == ItemKind.CHANGE_SPEED:
            s = it["param2"]
            if not (s == -1 or (math.isfinite(s) and 0.1 <= s <= 20.0)):
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM2, f"speed {s} outside [0.1, 20] m/s")
            return
        if kind == ItemKind.RTL:
            return
        if cmd == mav.MAV_CMD_NAV_DELAY:
            if not (math.isfinite(it["param1"]) and 0 <= it["param1"] <= 86400):
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, f"delay {it['param1']} s (no time of day)")
            return
        if frame not in POSITION_FRAMES:
            raise ItemError(mav.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {frame} not supported")
        if kind in (ItemKind.WAYPOINT, ItemKind.LOITER_TIME):
            if not (math.isfinite(it["param1"]) and 0 <= it["param1"] <= 86400):
                raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, f"hold time {it['param1']}")
            _check_latlon(it)
        if kind == ItemKind.WAYPOINT and not (math.isfinite(it["param2"]) and 0 <= it["param2"] <= 1000):
            raise ItemError(mav.MAV_MISSION_INVALID_PARAM2, f"acceptance radius {it['param2']}")
        if kind == ItemKind.LAND and (it["lat"] != 0 or it["lon"] != 0):
            _check_latlon(it)
        if not math.isfinite(it["z"]) or abs(it["z"]) > 1e4:
            raise ItemError(mav.MAV_MISSION_INVALID_PARAM7, f"altitude {it['z']}")

    def _install(self, mtype: int, items: list[dict]) -> None:
        if mtype == FENCE:
            self.geofence.load(self._fence_from(items))
            self.plans[FENCE] = items
            return
        mission = [self._to_item(it) for it in items]
        self.plans[MISSION] = items
        fc = self.ap.fc
        was_flying = fc.mode == Mode.MISSION and fc.armed
        fc.set_mission(mission)
        if was_flying:
            fc.hold() if not mission else fc.start_mission(0)
        self.ap.mission_changed()

    def _ned(self, it: dict) -> np.ndarray:
        home = self.ap.home
        ned = geodetic_to_ned(it["lat"], it["lon"], home.alt_m, home)
        if it["frame"] in RELATIVE_FRAMES:
            ned[2] = self.ap.fc.home[2] - it["z"]
        else:
            ned[2] = home.alt_m - it["z"]
        return ned

    def land_start_index(self) -> int | None:
        """Index of the mission's DO_LAND_START item (the first one), None without one."""
        for i, it in enumerate(self.plans[MISSION]):
            if it["command"] == MAV_CMD_DO_LAND_START:
                return i
        return None

    def _to_item(self, it: dict) -> MissionItem:
        if it["command"] == MAV_CMD_DO_LAND_START:
            # A no-op item keeps the autopilot's indices equal to the plan's: a speed change to "no change".
            return MissionItem(ItemKind.CHANGE_SPEED, speed_m_s=math.nan)
        kind = NAV_KINDS[it["command"]]
        if kind == ItemKind.CHANGE_SPEED:
            s = it["param2"]
            return MissionItem(kind, speed_m_s=math.nan if s == -1 else float(s))
        if kind == ItemKind.RTL:
            return MissionItem(kind)
        if it["command"] == mav.MAV_CMD_NAV_DELAY:
            return MissionItem(kind, hold_s=float(it["param1"]), acceptance_radius_m=1.0)
        ned = self._ned(it)
        yaw = math.radians(it["param4"]) if math.isfinite(it["param4"]) else math.nan
        if kind == ItemKind.TAKEOFF:
            return MissionItem(kind, np.array([math.nan, math.nan, ned[2]]), acceptance_radius_m=0.5, yaw_rad=yaw)
        if kind == ItemKind.LAND:
            pos = np.full(3, math.nan)
            if it["lat"] != 0 or it["lon"] != 0:
                pos[0:2] = ned[0:2]
            return MissionItem(kind, pos, yaw_rad=yaw)
        radius = it["param2"] if kind == ItemKind.WAYPOINT and it["param2"] > 0 else 1.0
        return MissionItem(kind, ned, acceptance_radius_m=float(radius), hold_s=float(it["param1"]), yaw_rad=yaw)

    def _fence_from(self, items: list[dict]) -> Geofence:
        fence = Geofence()
        i = 0
        while i < len(items):
            it = items[i]
            cmd = it["command"]
            if cmd in (mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION):
                fence.add_circle(self._ned(it)[0:2], it["param1"], cmd == mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION)
                i += 1
            elif cmd == mav.MAV_CMD_NAV_FENCE_RETURN_POINT:
                i += 1
            else:
                n = int(it["param1"])
                group = items[i:i + n]
                if len(group) < n or any(g["command"] != cmd or int(g["param1"]) != n for g in group):
                    raise ItemError(mav.MAV_MISSION_INVALID_PARAM1, f"polygon at {i} has inconsistent vertex count")
                pts = np.array([self._ned(g)[0:2] for g in group])
                fence.add_polygon(pts, cmd == mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION)
                i += n
        return fence

    # ------------------------------------------------------------------ download, clear, current
    def on_mission_request_list(self, msg: Any, link: Link) -> None:
        if not targets_us(msg):
            return
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype not in (MISSION, FENCE):
            self._ack(link, msg, mav.MAV_MISSION_UNSUPPORTED, mtype, f"Mission type {mtype} not supported")
            return
        self.ep.reply(
            mav.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), len(self.plans[mtype]),
                                            mtype), link)  # fmt: skip

    def on_mission_request_int(self, msg: Any, link: Link) -> None:
        if not targets_us(msg):
            return
        mtype = getattr(msg, "mission_type", MISSION)
        plan = self.plans.get(mtype)
        if plan is None:
            self._ack(link, msg, mav.MAV_MISSION_UNSUPPORTED, mtype, f"Mission type {mtype} not supported")
            return
        if not 0 <= msg.seq < len(plan):
            self._ack(link, msg, mav.MAV_MISSION_INVALID_SEQUENCE, mtype,
                      f"Requested item {msg.seq} out of bounds ({len(plan)})")  # fmt: skip
            return
        it = plan[msg.seq]
        fc = self.ap.fc
        self.ep.reply(
            mav.MAVLink_mission_item_int_message(
                msg.get_srcSystem(), msg.get_srcComponent(), msg.seq, it["frame"], it["command"],
                int(mtype == MISSION and msg.seq == fc.mission_index), it["autocontinue"],
                it["param1"], it["param2"], it["param3"], it["param4"],
                int(round(it["lat"] * 1e7)), int(round(it["lon"] * 1e7)), it["z"], mtype,
            ),
            link,
        )  # fmt: skip

    on_mission_request = on_mission_request_int

    def on_mission_clear_all(self, msg: Any, link: Link) -> None:
        if not targets_us(msg):
            return
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype == mav.MAV_MISSION_TYPE_ALL:
            self._install(MISSION, [])
            self._install(FENCE, [])
            mtype_ack = mtype
        elif mtype in (MISSION, FENCE):
            self._install(mtype, [])
            mtype_ack = mtype
        else:
            self._ack(link, msg, mav.MAV_MISSION_UNSUPPORTED, mtype, f"Mission type {mtype} not supported")
            return
        self._ack(link, msg, mav.MAV_MISSION_ACCEPTED, mtype_ack)

    def on_mission_set_current(self, msg: Any, link: Link) -> None:
        if not targets_us(msg):
            return
        fc = self.ap.fc
        if not 0 <= msg.seq < len(fc.mission):
            self._ack(link, msg, mav.MAV_MISSION_INVALID_SEQUENCE, MISSION,
                      f"Set current {msg.seq} out of bounds ({len(fc.mission)})")  # fmt: skip
            return
        if fc.mode == Mode.MISSION and fc.armed:
            fc.start_mission(msg.seq)
        else:
            fc.mission_index = msg.seq
        self.ep.send_many(self.mission_current())

    def on_mission_ack(self, msg: Any, link: Link) -> None:
        pass  # end of a download: nothing to release, downloads are stateless here


def _normalise(msg: Any, as_int: bool) -> dict:
    scale = 1e-7 if as_int else 1.0
    return {
        "frame": int(msg.frame), "command": int(msg.command), "autocontinue": int(msg.autocontinue),
        "param1": float(msg.param1), "param2": float(msg.param2), "param3": float(msg.param3),
        "param4": float(msg.param4), "lat": float(msg.x) * scale, "lon": float(msg.y) * scale, "z": float(msg.z),
    }  # fmt: skip


def _check_latlon(it: dict) -> None:
    if not (math.isfinite(it["lat"]) and -90.0 <= it["lat"] <= 90.0):
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM5_X, f"latitude {it['lat']}")
    if not (math.isfinite(it["lon"]) and -180.0 <= it["lon"] <= 180.0):
        raise ItemError(mav.MAV_MISSION_INVALID_PARAM6_Y, f"longitude {it['lon']}")
