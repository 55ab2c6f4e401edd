"""The MAVLink endpoint against a pymavlink peer, for what MAVSDK does not exercise: parameters,
REQUEST_MESSAGE, SET/GET_MESSAGE_INTERVAL, unsupported and refused commands, mission protocol
errors, mission download and clear, geofence upload and enforcement, offboard loss."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator

import numpy as np
import pytest
from link_support import free_port, running, udp_to, wait_until
from pymavlink import mavutil

import sitl.link.mission_protocol as mission_protocol
from sitl.autopilot.controller import SP_POS, SP_YAW
from sitl.autopilot.flight_modes import Mode
from sitl.link import SitlLink
from sitl.world.sensors import ned_to_geodetic
from wire.dialect import mavlink as M  # noqa: N812  (the MAVLink 2 constants and message classes)


class Peer:
    """A pymavlink ground station (system 255) on a UDP port the SITL streams to."""

    def __init__(self, port: int) -> None:
        os.environ["MAVLINK20"] = "1"  # mavutil picks the MAVLink 2 dialect only with this set
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
        self.mav = self.conn.mav
        assert self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=10) is not None

    def recv(self, mtype: str | list[str], timeout: float = 3.0, cond: object = None) -> object:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            m = self.conn.recv_match(type=mtype, blocking=True, timeout=max(0.01, t_end - time.monotonic()))
            if m is not None and (cond is None or cond(m)):
                return m
        raise AssertionError(f"no {mtype} within {timeout} s")

    def command(self, cmd: int, *params: float) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        self.drain()  # a full socket buffer (nobody read it while waiting) would drop the ACK
        self.mav.command_long_send(1, 1, cmd, 0, *p)
        return self.recv("COMMAND_ACK", cond=lambda m: m.command == cmd).result

    def drain(self) -> None:
        while self.conn.recv_match(blocking=False) is not None:
            pass


@pytest.fixture
def sitl() -> Iterator[tuple[SitlLink, Peer]]:
    port = free_port()
    with running([udp_to(port)], allow_sim_params=True) as link:
        # A pure-Python peer parses ~1500 messages/s at speed 4 slowly enough for its socket
        # buffer to overflow; these tests do not need the high-rate raw streams.
        for mid in (M.MAVLINK_MSG_ID_HIL_SENSOR, M.MAVLINK_MSG_ID_HIGHRES_IMU, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
                    M.MAVLINK_MSG_ID_ESC_STATUS, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT):
            link.streams.set_interval(mid, -1, 0.0)
        peer = Peer(port)
        wait_until(lambda: link.sim.t > 0.3, 5.0, "first GNSS fix")  # pre-arm needs a fix, as PX4
        yield link, peer
        peer.conn.close()


def _item(seq: int, cmd: int, lat: float = 0.0, lon: float = 0.0, alt: float = 0.0, frame: int = 6,
          p1: float = 0.0, p2: float = 0.0, mtype: int = 0) -> object:  # fmt: skip
    return M.MAVLink_mission_item_int_message(1, 1, seq, frame, cmd, 0, 1, p1, p2, 0.0, math.nan,
                                              int(lat * 1e7), int(lon * 1e7), alt, mtype)  # fmt: skip


def _upload(peer: Peer, items: list, mtype: int = 0) -> int:
    """Upload via the real protocol; returns the final MISSION_ACK type."""
    peer.mav.mission_count_send(1, 1, len(items), mtype)
    while True:
        m = peer.recv(["MISSION_REQUEST_INT", "MISSION_ACK"])
        if m.get_type() == "MISSION_ACK":
            return m.type
        peer.mav.send(items[m.seq])


def _geo(link: SitlLink, n: float, e: float) -> tuple[float, float]:
    lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), link.sim.scenario.sensors.home)
    return lat, lon


def test_parameters_list_read_set_echo(sitl: tuple[SitlLink, Peer]) -> None:
    link, peer = sitl
    peer.mav.param_request_list_send(1, 1)
    seen: dict[str, tuple[float, int, int]] = {}
    while True:
        m = peer.recv("PARAM_VALUE")
        seen[m.param_id] = (m.param_value, m.param_index, m.param_count)
        if len(seen) == m.param_count:
            break
    assert {"CTL_POS_P_XY", "MIS_TAKEOFF_ALT", "COM_OF_LOSS_T", "SIM_WIND_N", "SIM_SPEED", "SIM_ACC_NOISE"} <= set(seen)
    assert sorted(i for _, i, _ in seen.values()) == list(range(len(seen)))
    assert seen["CTL_POS_P_XY"][0] == pytest.approx(link.sim.gain("pos_p_xy"))

    peer.mav.param_set_send(1, 1, b"CTL_POS_P_XY", 1.25, M.MAV_PARAM_TYPE_REAL32)
    echo = peer.recv("PARAM_VALUE", cond=lambda m: m.param_id == "CTL_POS_P_XY")
    assert echo.param_value == pytest.approx(1.25)
    assert link.sim.gain("pos_p_xy") == pytest.approx(1.25)
    # A NaN or out-of-range value is refused: the echo carries the unchanged value.
    peer.mav.param_set_send(1, 1, b"CTL_POS_P_XY", math.nan, M.MAV_PARAM_TYPE_REAL32)
    assert peer.recv("PARAM_VALUE", cond=lambda m: m.param_id == "CTL_POS_P_XY").param_value == pytest.approx(1.25)
    peer.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 1e6, M.MAV_PARAM_TYPE_REAL32)
    assert peer.recv("PARAM_VALUE", cond=lambda m: m.param_id == "MIS_TAKEOFF_ALT").param_value == pytest.approx(3.0)
    assert link.counters["params_rejected"] == 2
    # Read by index.
    idx = seen["COM_OF_LOSS_T"][1]
    peer.mav.param_request_read_send(1, 1, b"", idx)
    assert peer.recv("PARAM_VALUE", cond=lambda m: m.param_index == idx).param_id == "COM_OF_LOSS_T"
    # Simulation knobs act live: the mean wind and the IMU noise.
    peer.mav.param_set_send(1, 1, b"SIM_WIND_E", 3.0, M.MAV_PARAM_TYPE_REAL32)
    peer.recv("PARAM_VALUE", cond=lambda m: m.param_id == "SIM_WIND_E")
    assert link.sim.wind_at_vehicle[1] == pytest.approx(3.0, abs=0.3)
    peer.mav.param_set_send(1, 1, b"SIM_ACC_NOISE", 0.5, M.MAV_PARAM_TYPE_REAL32)
    peer.recv("PARAM_VALUE", cond=lambda m: m.param_id == "SIM_ACC_NOISE")
    assert link.sim.sensors.config.imu.accel_noise_m_s2 == 0.5


def test_request_message_and_message_intervals(sitl: tuple[SitlLink, Peer]) -> None:
    link, peer = sitl
    assert peer.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == M.MAV_RESULT_ACCEPTED
    ver = peer.recv("AUTOPILOT_VERSION")
    assert ver.capabilities & M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    assert ver.capabilities & M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert peer.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION) == M.MAV_RESULT_ACCEPTED
    home = peer.recv("HOME_POSITION")
    assert home.latitude == int(link.sim.scenario.sensors.home.lat_deg * 1e7)
    assert peer.command(M.MAV_CMD_REQUEST_MESSAGE, 9999) == M.MAV_RESULT_DENIED
    assert peer.command(M.MAV_CMD_REQUEST_MESSAGE, math.nan) == M.MAV_RESULT_DENIED

    # ATTITUDE to 10 Hz (simulation time) and HIL_SENSOR off.
    assert peer.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 100_000) == M.MAV_RESULT_ACCEPTED
    assert peer.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HIL_SENSOR, -1) == M.MAV_RESULT_ACCEPTED
    assert peer.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, 9999, 1000) == M.MAV_RESULT_DENIED
    peer.drain()
    t0 = link.sim.t
    n_att = n_hil = 0
    t_end = time.monotonic() + 1.0
    while time.monotonic() < t_end:
        m = peer.conn.recv_match(blocking=True, timeout=0.1)
        if m is not None:
            n_att += m.get_type() == "ATTITUDE"
            n_hil += m.get_type() == "HIL_SENSOR"
    rate = n_att / (link.sim.t - t0)
    assert rate == pytest.approx(10.0, rel=0.25)
    assert n_hil == 0
    peer.mav.command_long_send(1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_ATTITUDE, 0, 0, 0, 0, 0, 0)
    iv = peer.recv("MESSAGE_INTERVAL", cond=lambda m: m.message_id == M.MAVLINK_MSG_ID_ATTITUDE)
    assert iv.interval_us == 100_000
    # 0 restores the default (100 Hz, PX4 onboard).
    assert peer.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 0) == M.MAV_RESULT_ACCEPTED
    assert link.streams.interval_us(M.MAVLINK_MSG_ID_ATTITUDE) == 10_000


def test_unsupported_and_refused_commands(sitl: tuple[SitlLink, Peer]) -> None:
    link, peer = sitl
    assert peer.command(M.MAV_CMD_DO_DIGICAM_CONTROL) == M.MAV_RESULT_UNSUPPORTED
    assert peer.command(31337) == M.MAV_RESULT_UNSUPPORTED
    assert peer.command(M.MAV_CMD_NAV_TAKEOFF) == M.MAV_RESULT_DENIED  # not armed
    assert peer.command(M.MAV_CMD_COMPONENT_ARM_DISARM, math.nan) == M.MAV_RESULT_DENIED
    assert peer.command(M.MAV_CMD_DO_SET_MODE, 1, 99, 0) == M.MAV_RESULT_DENIED  # no such PX4 mode
    assert peer.command(M.MAV_CMD_DO_SET_MODE, 1, 6, 0) == M.MAV_RESULT_TEMPORARILY_REJECTED  # no setpoints
    assert peer.command(M.MAV_CMD_DO_CHANGE_SPEED, 1, 500.0) == M.MAV_RESULT_DENIED
    assert peer.command(M.MAV_CMD_MISSION_START) == M.MAV_RESULT_DENIED  # no mission
    assert not link.sim.fc.armed
    assert link.counters["handler_errors"] == 0


def test_mission_errors_download_clear(sitl: tuple[SitlLink, Peer], monkeypatch: pytest.MonkeyPatch) -> None:
    link, peer = sitl
    lat, lon = _geo(link, 5.0, 0.0)
    wp = M.MAV_CMD_NAV_WAYPOINT
    unknown = [_item(0, M.MAV_CMD_NAV_TAKEOFF, alt=3), _item(1, 31000, lat, lon, 3)]
    assert _upload(peer, unknown) == M.MAV_MISSION_UNSUPPORTED
    assert _upload(peer, [_item(0, wp, lat, lon, 3, frame=M.MAV_FRAME_BODY_FRD)]) == M.MAV_MISSION_UNSUPPORTED_FRAME
    assert _upload(peer, [_item(0, wp, 95.0, lon, 3)]) == M.MAV_MISSION_INVALID_PARAM5_X
    assert _upload(peer, [_item(0, wp, lat, lon, math.nan)]) == M.MAV_MISSION_INVALID_PARAM7
    assert _upload(peer, [_item(0, wp, lat, lon, 3, p1=-4.0)]) == M.MAV_MISSION_INVALID_PARAM1
    assert not link.sim.fc.mission, "a refused upload must not replace the plan"
    # Out-of-sequence item.
    peer.mav.mission_count_send(1, 1, 2, 0)
    peer.recv("MISSION_REQUEST_INT", cond=lambda m: m.seq == 0)
    peer.mav.send(_item(1, wp, lat, lon, 3))
    assert peer.recv("MISSION_ACK").type == M.MAV_MISSION_INVALID_SEQUENCE
    # Rally points are not supported.
    peer.mav.mission_count_send(1, 1, 1, M.MAV_MISSION_TYPE_RALLY)
    assert peer.recv("MISSION_ACK").type == M.MAV_MISSION_UNSUPPORTED
    # Timeout: the request is retried, then the transfer is cancelled.
    monkeypatch.setattr(mission_protocol, "REQUEST_TIMEOUT_S", 0.05)
    peer.mav.mission_count_send(1, 1, 1, 0)
    reqs = 0
    while True:
        m = peer.recv(["MISSION_REQUEST_INT", "MISSION_ACK"])
        if m.get_type() == "MISSION_ACK":
            break
        reqs += 1
    assert m.type == M.MAV_MISSION_OPERATION_CANCELLED and reqs == mission_protocol.REQUEST_RETRIES + 1
    monkeypatch.undo()

    good = [_item(0, M.MAV_CMD_NAV_TAKEOFF, alt=3), _item(1, wp, lat, lon, 4, p1=2.0, p2=0.7),
            _item(2, M.MAV_CMD_DO_CHANGE_SPEED, frame=2, p2=2.5), _item(3, M.MAV_CMD_NAV_LAND, frame=6)]  # fmt: skip
    assert _upload(peer, good) == M.MAV_MISSION_ACCEPTED
    fc = link.sim.fc
    assert [i.kind.value for i in fc.mission] == ["takeoff", "waypoint", "change_speed", "land"]
    assert fc.mission[1].position_ned == pytest.approx([5.0, 0.0, -4.0], abs=0.01)
    assert fc.mission[1].hold_s == 2.0 and fc.mission[1].acceptance_radius_m == pytest.approx(0.7)
    # Download returns what was uploaded.
    peer.mav.mission_request_list_send(1, 1, 0)
    assert peer.recv("MISSION_COUNT").count == 4
    for seq, it in enumerate(good):
        peer.mav.mission_request_int_send(1, 1, seq, 0)
        got = peer.recv("MISSION_ITEM_INT", cond=lambda m, s=seq: m.seq == s)
        assert (got.command, got.x, got.y, got.z, got.frame) == (it.command, it.x, it.y, it.z, it.frame)
    peer.mav.mission_request_int_send(1, 1, 7, 0)
    assert peer.recv("MISSION_ACK").type == M.MAV_MISSION_INVALID_SEQUENCE
    peer.mav.mission_ack_send(1, 1, 0, 0)
    # Set current (message and command), then clear.
    peer.mav.mission_set_current_send(1, 1, 1)
    assert peer.recv("MISSION_CURRENT", cond=lambda m: m.seq == 1).total == 4
    assert peer.command(M.MAV_CMD_DO_SET_MISSION_CURRENT, 2) == M.MAV_RESULT_ACCEPTED
    assert fc.mission_index == 2
    assert peer.command(M.MAV_CMD_DO_SET_MISSION_CURRENT, 9) == M.MAV_RESULT_DENIED
    peer.mav.mission_clear_all_send(1, 1, 0)
    assert peer.recv("MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    assert fc.mission == []


def test_geofence_upload_and_breach_holds(sitl: tuple[SitlLink, Peer]) -> None:
    link, peer = sitl
    lat, lon = _geo(link, 0.0, 0.0)
    fence = [_item(0, M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, lat, lon, 0, frame=5, p1=4.0, mtype=1)]
    assert _upload(peer, fence, mtype=1) == M.MAV_MISSION_ACCEPTED
    peer.mav.mission_request_list_send(1, 1, 1)
    assert peer.recv("MISSION_COUNT", cond=lambda m: m.mission_type == 1).count == 1
    assert peer.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert peer.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan) == M.MAV_RESULT_ACCEPTED
    wait_until(lambda: link.sim.fc.mode == Mode.HOLD and link.sim.position[2] < -2.5, 15.0, "take-off")
    # Fly north at 2 m/s in offboard until the fence stops it.
    mask = 0b0000_1111_1100_0111  # velocity only, yaw ignored
    sp = lambda: peer.mav.set_position_target_local_ned_send(0, 1, 1, 1, mask, 0, 0, 0, 2.0, 0, 0, 0, 0, 0, 0, 0)  # noqa: E731
    for _ in range(5):
        sp()
        time.sleep(0.02)
    assert peer.command(M.MAV_CMD_DO_SET_MODE, 1, 6, 0) == M.MAV_RESULT_ACCEPTED
    t_end = time.monotonic() + 10.0
    text = None
    while time.monotonic() < t_end and text is None:
        sp()
        m = peer.conn.recv_match(type="STATUSTEXT", blocking=True, timeout=0.05)
        if m is not None and "Geofence" in m.text:
            text = m
    assert text is not None and text.severity == M.MAV_SEVERITY_WARNING
    assert link.sim.fc.mode == Mode.HOLD
    assert 3.5 < link.sim.position[0] < 6.0
    assert link.geofence.breaches == 1


def test_offboard_stream_loss_falls_back_to_hold(sitl: tuple[SitlLink, Peer]) -> None:
    link, peer = sitl
    assert peer.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert peer.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan) == M.MAV_RESULT_ACCEPTED
    wait_until(lambda: link.sim.fc.mode == Mode.HOLD and link.sim.position[2] < -2.5, 15.0, "take-off")
    mask = 0b0000_1101_1111_1000  # position only
    for _ in range(5):
        peer.mav.set_position_target_local_ned_send(0, 1, 1, 1, mask, 1.0, 0, -3.0, 0, 0, 0, 0, 0, 0, 0, 0)
        time.sleep(0.02)
    t_stop = link.sim.t  # the last setpoint has arrived by now (or within one 10 ms chunk)
    assert peer.command(M.MAV_CMD_DO_SET_MODE, 1, 6, 0) == M.MAV_RESULT_ACCEPTED
    hb = peer.recv("HEARTBEAT", cond=lambda m: m.custom_mode == 6 << 16)
    assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED and hb.system_status == M.MAV_STATE_ACTIVE
    txt = peer.recv("STATUSTEXT", timeout=5.0, cond=lambda m: "Offboard" in m.text)
    assert "Hold" in txt.text
    # Allow for the 20 ms wall (80 ms simulated) sleep after the last setpoint.
    assert 0.85 <= link.sim.t - t_stop <= link.sim.fc.config.offboard_timeout_s + 0.5
    peer.recv("HEARTBEAT", cond=lambda m: m.custom_mode == (4 << 16) | (3 << 24))


def test_heartbeat_sys_status_prearm_and_landed_state(sitl: tuple[SitlLink, Peer]) -> None:
    link, peer = sitl
    hb = peer.recv("HEARTBEAT", cond=lambda m: m.get_srcSystem() == 1)
    assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    st = peer.recv("SYS_STATUS")
    needed = 0x1 | 0x2 | 0x4 | 0x8 | 0x20 | 0x200000 | 0x10000000  # what MAVSDK's health checks read
    assert st.onboard_control_sensors_present & needed == needed
    assert st.onboard_control_sensors_health & needed == needed
    assert peer.recv("EXTENDED_SYS_STATE").landed_state == M.MAV_LANDED_STATE_ON_GROUND
    # A failing pre-arm check clears the pre-arm health bit and makes arming fail with a STATUSTEXT.
    link.sim.fc.prearm_checks.append(lambda: "test interlock")
    peer.drain()
    assert not peer.recv("SYS_STATUS").onboard_control_sensors_health & 0x10000000
    assert peer.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_DENIED
    assert "test interlock" in peer.recv("STATUSTEXT", cond=lambda m: "Preflight" in m.text).text
    link.sim.fc.prearm_checks.pop()
    assert peer.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    hb = peer.recv("HEARTBEAT", cond=lambda m: m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb.system_status == M.MAV_STATE_ACTIVE
    assert peer.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED


def test_global_and_attitude_setpoints_are_converted(sitl: tuple[SitlLink, Peer]) -> None:
    link, peer = sitl
    fc = link.sim.fc
    lat, lon = _geo(link, 7.0, -2.0)
    pos_yaw = 0b0000_1001_1111_1000  # position and yaw used; velocity, acceleration, yaw rate ignored
    frame = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    peer.mav.set_position_target_global_int_send(0, 1, 1, frame, pos_yaw, int(lat * 1e7), int(lon * 1e7), 5.0,
                                                 0, 0, 0, 0, 0, 0, 1.0, 0)  # fmt: skip
    wait_until(lambda: link.counters["setpoints"] >= 1, 2.0, "global setpoint")
    sp = fc._offb_sp  # the offboard setpoint vector the flight controller stored (sitl.autopilot.controller layout)

    assert sp[SP_POS:SP_POS + 3] == pytest.approx([7.0, -2.0, -5.0], abs=0.02)
    assert sp[SP_YAW] == pytest.approx(1.0)
    peer.mav.set_attitude_target_send(0, 1, 1, 0b0000_0111, [1.0, 0.0, 0.0, 0.0], 0, 0, 0, 0.6)
    wait_until(lambda: link.counters["setpoints"] >= 2, 2.0, "attitude setpoint")
    # Refused: a non-unit quaternion, a thrust above 1, a rate-only command.
    peer.mav.set_attitude_target_send(0, 1, 1, 0b0000_0111, [3.0, 0.0, 0.0, 0.0], 0, 0, 0, 0.6)
    peer.mav.set_attitude_target_send(0, 1, 1, 0b0000_0111, [1.0, 0.0, 0.0, 0.0], 0, 0, 0, 1.5)
    peer.mav.set_attitude_target_send(0, 1, 1, 0b1000_0000, [1.0, 0.0, 0.0, 0.0], 0.1, 0, 0, 0.5)
    wait_until(lambda: link.counters["setpoints_rejected"] >= 3, 2.0, "rejections counted")
    assert link.counters["setpoints"] == 2
