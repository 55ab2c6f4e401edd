"""A minimal pymavlink ground station for ArduCopter (tests, benchmarks, scripts): a thin adapter.

What MAVProxy does for a user, reduced to what windseek's checks need: it reads the link all the
time, sends heartbeats, sets ArduCopter's modes by number, arms when the vehicle is ready, commands
a take-off and uploads a mission with the MAVLink mission protocol (:func:`upload_items`; PX4's
ground station in ``benchmarks/px4_lockstep.py`` uploads with it too, without ArduPilot's home item).
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections import deque
from typing import Any

from wire.dialect import mavlink

#: ArduCopter's custom modes (ArduCopter/mode.h).
COPTER_MODES = {"STABILIZE": 0, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6, "LAND": 9, "BRAKE": 17}


def upload_items(
    send: Any, wait: Any, target_system: int, items: list[tuple[float, ...]], timeout_s: float = 20.0
) -> int | None:
    """The MAVLink mission protocol's upload, as the ground station's side: MISSION_COUNT, then each requested
    item as MISSION_ITEM_INT, until the MISSION_ACK; its type (None if the autopilot fell silent).

    ``items``: (command, lat deg, lon deg, alt m relative[, param1[, param2]]) numbered from 0 as given (ArduPilot
    takes item 0 for home, PX4 flies it). ``send(fn, *args)`` sends with pymavlink's ``mav.<fn>``; ``wait(types,
    timeout_s)`` gives the next message of those types that came after the caller cleared its queue, or None.
    A navigation command (``MAV_CMD_NAV_*``, below 100) is placed relative to home
    (``MAV_FRAME_GLOBAL_RELATIVE_ALT_INT``); any other in ``MAV_FRAME_MISSION``: PX4 refuses a DO_CHANGE_SPEED in
    a global frame (``MAV_MISSION_UNSUPPORTED``, mavlink_mission.cpp), ArduPilot reads the frame only of the
    commands that carry a place (AP_Mission ``stored_in_location``)."""
    send("mission_count_send", target_system, 1, len(items), 0)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        r = wait(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], 5.0)
        if r is None:
            return None
        if r.get_type() == "MISSION_ACK":
            return int(r.type)
        if not 0 <= r.seq < len(items):
            continue
        cmd, lat, lon, alt, p1, p2 = (*items[r.seq], 0.0, 0.0)[:6]
        frame = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT if cmd < 100 else mavlink.MAV_FRAME_MISSION
        send("mission_item_int_send", target_system, 1, r.seq, frame, int(cmd), 0, 1, p1, p2, 0, 0,
             int(round(lat * 1e7)), int(round(lon * 1e7)), alt, 0)  # fmt: skip
    return None


def next_answer(cv: threading.Condition, queue: deque[Any], types: list[str] | str, timeout_s: float,
                cond: Any = None) -> Any:  # fmt: skip
    """The next message in ``queue`` (filled by a reader thread that notifies ``cv``) of ``types`` and satisfying
    ``cond``, within ``timeout_s`` wall seconds; None if none came. Messages taken before it are dropped."""
    deadline = time.monotonic() + timeout_s
    want = [types] if isinstance(types, str) else types
    with cv:
        while True:
            while queue:
                msg = queue.popleft()
                if msg.get_type() in want and (cond is None or cond(msg)):
                    return msg
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            cv.wait(left)


class CopterGcs:
    """A pymavlink ground station on ArduCopter's SERIAL0 (MAVLink 2), with ArduCopter's mode numbers.

    A thread reads the link all the time (ArduPilot SITL slows itself down while its SERIAL0 queue is
    over 1 kB: a ground station that does not read pauses the simulation) into a bounded queue (oldest
    dropped, counted), and sends a heartbeat 5 times per wall second (ArduCopter's ground-station
    failsafe runs on its simulated clock)."""

    def __init__(self, port: int, timeout_s: float = 30.0, keep: int = 20000) -> None:
        os.environ["MAVLINK20"] = "1"
        from pymavlink import mavutil

        deadline = time.monotonic() + timeout_s
        while True:
            try:
                self.m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255, source_component=190,
                                                    retries=0)  # fmt: skip
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        self.text: list[str] = []
        self.queue: deque[Any] = deque(maxlen=keep)
        self.dropped = 0
        self._cv = threading.Condition()
        self._stop = threading.Event()
        self._lock = threading.Lock()  # pymavlink's connection is not thread-safe for sending
        self._threads = [threading.Thread(target=self._read, daemon=True), threading.Thread(target=self._beat,
                                                                                            daemon=True)]
        for t in self._threads:
            t.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.m.recv_match(blocking=True, timeout=0.2)
            except (OSError, ValueError):
                break
            if msg is None:
                continue
            if msg.get_type() == "STATUSTEXT":
                self.text.append(msg.text)
            with self._cv:
                if len(self.queue) == self.queue.maxlen:
                    self.dropped += 1
                self.queue.append(msg)
                self._cv.notify_all()

    def _beat(self) -> None:
        while not self._stop.wait(0.2):
            with contextlib.suppress(OSError):
                self.heartbeat()

    def recv(self, types: list[str] | str | None = None, timeout_s: float = 5.0, cond: Any = None) -> Any:
        """The first message from now on of ``types`` satisfying ``cond`` within ``timeout_s`` (None if none)."""
        deadline = time.monotonic() + timeout_s
        want = [types] if isinstance(types, str) else types
        with self._cv:
            self.queue.clear()
            while True:
                while self.queue:
                    msg = self.queue.popleft()
                    if (want is None or msg.get_type() in want) and (cond is None or cond(msg)):
                        return msg
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cv.wait(left)

    def send(self, fn: str, *args: Any) -> None:
        with self._lock:
            getattr(self.m.mav, fn)(*args)

    def heartbeat(self) -> None:
        self.send("heartbeat_send", mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def command(self, cmd: int, *params: float, timeout_s: float = 5.0) -> int | None:
        """COMMAND_LONG; its COMMAND_ACK result (None if none came)."""
        p = list(params) + [0.0] * (7 - len(params))
        with self._cv:
            self.queue.clear()
        self.send("command_long_send", self.m.target_system or 1, 1, cmd, 0, *p)
        ack = self._wait("COMMAND_ACK", timeout_s, lambda a: a.command == cmd)
        return None if ack is None else int(ack.result)

    def _wait(self, types: list[str] | str, timeout_s: float, cond: Any = None) -> Any:
        """Like :meth:`recv` without clearing what came since the last clear (answers to a request)."""
        return next_answer(self._cv, self.queue, types, timeout_s, cond)

    def set_mode(self, name: str) -> int | None:
        return self.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, COPTER_MODES[name])

    def request_streams(self, rate_hz: int = 10) -> None:
        """All of ArduPilot's data streams on this link at ``rate_hz`` (of ArduPilot's clock), as MAVProxy asks."""
        self.send("request_data_stream_send", self.m.target_system or 1, 1, mavlink.MAV_DATA_STREAM_ALL, rate_hz, 1)

    def arm_when_ready(self, mode: str = "GUIDED", timeout_s: float = 90.0) -> int | None:
        """Arm in ``mode`` (retried once a wall second while ArduCopter's checks refuse: EKF and GPS settle
        first). The mode is set again before each try: when the simulated RC input comes up, ArduCopter
        takes the mode of its flight-mode switch (``FLTMODE*``), whatever was set before."""
        deadline = time.monotonic() + timeout_s
        r = None
        while time.monotonic() < deadline:
            if self.set_mode(mode) != 0 or self.recv("HEARTBEAT", 2.0, lambda h: h.get_srcComponent() == 1
                                                     and h.custom_mode == COPTER_MODES[mode]) is None:  # fmt: skip
                time.sleep(1.0)
                continue
            r = self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            if r == 0:
                return 0
            time.sleep(1.0)
        return r

    def guided_takeoff(self, altitude_m: float, timeout_s: float = 180.0) -> None:
        """Lock on to the autopilot, ask for its streams, arm in GUIDED when ready and take off to
        ``altitude_m`` above home; RuntimeError (with its last messages) on the way."""
        hb = self.recv("HEARTBEAT", 60.0, lambda h: h.get_srcComponent() == 1)
        if hb is None:
            raise RuntimeError("no heartbeat from ArduCopter")
        self.m.target_system = hb.get_srcSystem()
        self.request_streams(4)
        if self.arm_when_ready("GUIDED", timeout_s) != 0:
            raise RuntimeError(f"ArduCopter did not arm: {self.text[-5:]}")
        if self.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, float(altitude_m)) != 0:
            raise RuntimeError(f"take-off refused: {self.text[-5:]}")

    def upload_mission(self, items: list[tuple[float, ...]], timeout_s: float = 20.0) -> int | None:
        """(command, lat deg, lon deg, alt m relative[, param1[, param2]]) items after a home item 0 (param1 of a
        waypoint: its hold time, s; param2 of DO_CHANGE_SPEED: the speed, m/s); the MISSION_ACK type."""
        with self._cv:
            self.queue.clear()
        return upload_items(self.send, self._wait, self.m.target_system or 1,
                            [(mavlink.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0), *items], timeout_s)  # fmt: skip

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(2.0)
        self.m.close()
