"""QGroundControl's handshakes, replayed with pymavlink (QGC itself cannot run here).

The sequence is QGC's ``InitialConnectStateMachine`` (src/Vehicle/InitialConnectStateMachine.cc):
REQUEST_MESSAGE(AUTOPILOT_VERSION) to component 1, component information (REQUEST_MESSAGE
COMPONENT_METADATA, then COMPONENT_INFORMATION), standard modes (REQUEST_MESSAGE AVAILABLE_MODES),
the parameters (ParameterManager: PARAM_REQUEST_LIST, then PARAM_REQUEST_READ by index for any
missing), the mission, the geofence (PlanManager: MISSION_REQUEST_LIST / MISSION_REQUEST_INT /
MISSION_ACK per plan type, the fence only if AUTOPILOT_VERSION says MISSION_FENCE), and rally
points only with MISSION_RALLY. Every answer must come at once and be addressed to QGC (255:190).
Also QGC's MAVLink FTP (FTPManager; its "Onboard Files" lists ``/``) against the PX4-style server.
"""

from __future__ import annotations

import math
import os
import struct
import time
import zlib
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from link_support import free_port, quiet_running, wait_until
from pymavlink import mavutil

from sitl.link import SitlLink
from sitl.link import ftp as F  # noqa: N812
from sitl.world.sensors import ned_to_geodetic
from wire import param_codec
from wire.dialect import mavlink as M  # noqa: N812

QGC = (255, 190)  # QGC's system id and MAV_COMP_ID_MISSIONPLANNER
MAV_CMD_REQUEST_MESSAGE = 512
COMPONENT_METADATA, COMPONENT_INFORMATION, AVAILABLE_MODES = 397, 395, 435


class Qgc:
    def __init__(self, port: int) -> None:
        os.environ["MAVLINK20"] = "1"
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=QGC[0],
                                               source_component=QGC[1], dialect="common")  # fmt: skip
        self.mav = self.conn.mav
        assert self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=10) is not None
        self.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE)

    def recv(self, mtype: str | list[str], cond: Any = None, timeout: float = 3.0) -> Any:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            m = self.conn.recv_match(type=mtype, blocking=True, timeout=max(0.01, t_end - time.monotonic()))
            if m is not None and (cond is None or cond(m)):
                return m
        raise AssertionError(f"no {mtype} within {timeout} s")

    def request_message(self, msg_id: int) -> int:
        """QGC's Vehicle::requestMessage: COMMAND_LONG REQUEST_MESSAGE to component 1; the ACK's result."""
        self.mav.command_long_send(1, 1, MAV_CMD_REQUEST_MESSAGE, 0, msg_id, 0, 0, 0, 0, 0, 0)
        ack = self.recv("COMMAND_ACK", lambda a: a.command == MAV_CMD_REQUEST_MESSAGE)
        assert (ack.target_system, ack.target_component) == QGC
        return int(ack.result)

    def download(self, mission_type: int) -> list[Any]:
        """PlanManager's read: MISSION_REQUEST_LIST, MISSION_REQUEST_INT per item, MISSION_ACK."""
        self.mav.mission_request_list_send(1, 1, mission_type)
        count = self.recv("MISSION_COUNT", lambda m: m.mission_type == mission_type)
        assert (count.target_system, count.target_component) == QGC
        items = []
        for seq in range(count.count):
            self.mav.mission_request_int_send(1, 1, seq, mission_type)
            items.append(self.recv("MISSION_ITEM_INT", lambda m, s=seq: m.seq == s and m.mission_type == mission_type))
        self.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, mission_type)
        return items

    def upload(self, items: list[Any], mission_type: int) -> int:
        self.mav.mission_count_send(1, 1, len(items), mission_type)
        while True:
            m = self.recv(["MISSION_REQUEST_INT", "MISSION_ACK"])
            assert (m.target_system, m.target_component) == QGC
            if m.get_type() == "MISSION_ACK":
                return int(m.type)
            self.mav.send(items[m.seq])

    def ftp(self, op: F.Op) -> list[F.Op]:
        """One FTP request; the replies (a burst gives several)."""
        self.mav.file_transfer_protocol_send(0, 1, 1, op.pack())
        out = [F.Op.parse(self.recv("FILE_TRANSFER_PROTOCOL").payload)]
        while op.opcode == F.BURST and out[-1].opcode == F.ACK and not out[-1].burst_complete:
            out.append(F.Op.parse(self.recv("FILE_TRANSFER_PROTOCOL").payload))
        return out


@pytest.fixture
def sitl() -> Iterator[tuple[SitlLink, Qgc]]:
    port = free_port()
    with quiet_running(port) as link:
        qgc = Qgc(port)
        yield link, qgc
        qgc.conn.close()


def _item(link: SitlLink, seq: int, cmd: int, n: float, e: float, alt: float, mtype: int = 0,
          p1: float = 0.0) -> Any:  # fmt: skip
    lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), link.sim.scenario.sensors.home)
    return M.MAVLink_mission_item_int_message(1, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1, p1, 0.8, 0,
                                              math.nan, int(lat * 1e7), int(lon * 1e7), alt, mtype)  # fmt: skip


def test_qgc_initial_connect_sequence(sitl: tuple[SitlLink, Qgc]) -> None:
    link, qgc = sitl
    # 1. AUTOPILOT_VERSION: ACK then the message; PX4's version word and capabilities.
    assert qgc.request_message(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == M.MAV_RESULT_ACCEPTED
    av = qgc.recv("AUTOPILOT_VERSION")
    assert av.flight_sw_version >> 24 == 1 and av.flight_sw_version & 0xFF == 255  # 1.x, FIRMWARE_VERSION_TYPE_OFFICIAL
    caps = av.capabilities
    for bit in (M.MAV_PROTOCOL_CAPABILITY_MAVLINK2, M.MAV_PROTOCOL_CAPABILITY_MISSION_INT,
                M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE, M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
                M.MAV_PROTOCOL_CAPABILITY_FTP, M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT):
        assert caps & bit, f"capability {bit} missing"
    assert not caps & M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY  # so QGC skips the rally download
    # 2./3. Component information and standard modes: refused at once (QGC falls back to its PX4
    # plugin), by the ACK alone: no STATUSTEXT noise for a probe.
    for mid in (COMPONENT_METADATA, COMPONENT_INFORMATION, AVAILABLE_MODES):
        assert qgc.request_message(mid) == M.MAV_RESULT_DENIED
    # 4. Parameters: the whole list, then one re-read by index (QGC's missing-parameter path).
    qgc.mav.param_request_list_send(1, 0)  # QGC targets MAV_COMP_ID_ALL
    seen: dict[int, Any] = {}
    while True:
        m = qgc.recv("PARAM_VALUE")
        seen[m.param_index] = m
        if len(seen) == m.param_count:
            break
    assert sorted(seen) == list(range(len(link.params.params)))
    idx = next(i for i, m in seen.items() if m.param_id == "GF_ACTION")
    qgc.mav.param_request_read_send(1, 0, b"", idx)
    gf = qgc.recv("PARAM_VALUE", lambda m: m.param_index == idx)
    assert gf.param_type == M.MAV_PARAM_TYPE_INT32 and param_codec.decode(gf.param_value, gf.param_type) == 2
    # QGC sets with the type it learned and PX4's bytewise union.
    qgc.mav.param_set_send(1, 1, b"GF_ACTION", param_codec.encode(3, gf.param_type), gf.param_type)
    echo = qgc.recv("PARAM_VALUE", lambda m: m.param_id == "GF_ACTION")
    assert param_codec.decode(echo.param_value, echo.param_type) == 3 and link.geofence.action == 3
    # 5./6. Mission and geofence downloads (empty), then a plan written and read back as QGC does.
    assert qgc.download(M.MAV_MISSION_TYPE_MISSION) == []
    assert qgc.download(M.MAV_MISSION_TYPE_FENCE) == []
    plan = [_item(link, 0, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 3), _item(link, 1, M.MAV_CMD_NAV_WAYPOINT, 8, 0, 3),
            _item(link, 2, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0)]  # fmt: skip
    assert qgc.upload(plan, M.MAV_MISSION_TYPE_MISSION) == M.MAV_MISSION_ACCEPTED
    fence = [_item(link, 0, M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 0, 0, 0, 1, p1=50.0)]
    assert qgc.upload(fence, M.MAV_MISSION_TYPE_FENCE) == M.MAV_MISSION_ACCEPTED
    back = qgc.download(M.MAV_MISSION_TYPE_MISSION)
    assert [m.command for m in back] == [p.command for p in plan]
    assert [(m.x, m.y) for m in back] == [(p.x, p.y) for p in plan]
    assert [m.command for m in qgc.download(M.MAV_MISSION_TYPE_FENCE)] == [M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION]
    assert link.counters["handler_errors"] == 0


def test_mavftp_as_px4(sitl: tuple[SitlLink, Qgc]) -> None:
    link, qgc = sitl

    def op(seq: int, opcode: int, data: bytes = b"", offset: int = 0, session: int = 0, size: int = -1) -> F.Op:
        return F.Op(seq, session, opcode, len(data) if size < 0 else size, 0, 0, offset, data)

    # An empty vehicle: the root lists nothing (EOF); MAVProxy's parameter file is not found, at once.
    (r,) = qgc.ftp(op(1, F.LIST, b"/"))
    assert (r.opcode, r.req_opcode, r.data[0], r.seq) == (F.NAK, F.LIST, F.ERR_EOF, 2)
    (r,) = qgc.ftp(op(2, F.OPEN_RO, b"@PARAM/param.pck?withdefaults=1"))
    assert (r.opcode, r.data[0]) == (F.NAK, F.ERR_FILE_NOT_FOUND)
    # Writes are refused, unknown opcodes too (MAVProxy's ListDirectoryWithTime), as PX4 does.
    (r,) = qgc.ftp(op(3, F.CREATE, b"/x.txt"))
    assert (r.opcode, r.data[0]) == (F.NAK, F.ERR_FILE_PROTECTED)
    (r,) = qgc.ftp(op(4, 16, b"/"))
    assert (r.opcode, r.data[0]) == (F.NAK, F.ERR_UNKNOWN_COMMAND)
    (r,) = qgc.ftp(op(5, F.READ, size=10))
    assert (r.opcode, r.data[0]) == (F.NAK, F.ERR_INVALID_SESSION)
    # A lost reply: the same request again gets the same answer (PX4's last-reply cache).
    (again,) = qgc.ftp(op(5, F.READ, size=10))
    assert again == r
    # A file in the tree: list, open, read, burst, CRC, terminate.
    content = bytes(range(256)) * 3
    link.ftp.files["/logs/run.txt"] = content
    (r,) = qgc.ftp(op(10, F.LIST, b"/"))
    assert r.opcode == F.ACK and r.data == b"Dlogs\0"
    (r,) = qgc.ftp(op(11, F.LIST, b"/logs"))
    assert r.data == b"Frun.txt\t768\0"
    (r,) = qgc.ftp(op(12, F.OPEN_RO, b"/logs/run.txt"))
    assert r.opcode == F.ACK and struct.unpack("<I", r.data)[0] == len(content)
    (r,) = qgc.ftp(op(13, F.OPEN_RO, b"/logs/run.txt"))
    assert (r.opcode, r.data[0]) == (F.NAK, F.ERR_NO_SESSIONS)  # one session, as PX4
    (r,) = qgc.ftp(op(14, F.READ, offset=700, size=100))
    assert r.opcode == F.ACK and r.data == content[700:]
    chunks = qgc.ftp(op(15, F.BURST, offset=0, size=239))
    assert b"".join(c.data for c in chunks) == content and chunks[-1].burst_complete == 1
    assert [c.offset for c in chunks] == [0, 239, 478, 717]
    (r,) = qgc.ftp(op(20, F.CRC32, b"/logs/run.txt"))
    assert struct.unpack("<I", r.data)[0] == zlib.crc32(content)
    (r,) = qgc.ftp(op(21, F.TERMINATE))
    assert r.opcode == F.ACK
    # A payload whose size field lies is refused, not trusted.
    bad = op(22, F.OPEN_RO, b"/x", size=250)
    qgc.mav.file_transfer_protocol_send(0, 1, 1, bad.pack()[:12] + [0] * 239)
    r = F.Op.parse(qgc.recv("FILE_TRANSFER_PROTOCOL").payload)
    assert (r.opcode, r.data[0]) == (F.NAK, F.ERR_INVALID_DATA_SIZE)
    wait_until(lambda: link.counters["ftp_requests"] >= 15, 2.0, "requests counted")
    assert link.counters["handler_errors"] == 0
