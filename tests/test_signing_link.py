"""MAVLink 2 signing on the SITL's links, with real sockets and pymavlink peers (issue 14.5).

Without signing an unconfigured system 66 armed the vehicle, uploaded and started a mission, set
SIM_SPEED=50 and force-disarmed it in the air. With a key every one of those frames is dropped
and counted, nothing answers it and it is never learned as a peer, while the key holder flies.
Also: wrong keys, replays, a forged far-future time stamp (pymavlink 2.4.50 would let it lock the
key holder out), PX4's unsigned allowlist (an unsigned HEARTBEAT is accepted but proves no ground
link), SIM_* locked without ``--allow-sim-params``, answers to the asking peer only, the bounded
expiring UDP peer table, and no key in the tlog, the exit summary or the output.
"""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from link_support import free_port, running, udp_to, wait_until
from pymavlink import mavutil

from sitl.link import SitlLink
from sitl.world.sensors import ned_to_geodetic
from wire import signing
from wire.dialect import mavlink as M  # noqa: N812

KEY = signing.parse_key("5e" * 16 + "0123456789abcdef" * 2, "test")
OTHER = signing.parse_key("77" * 32, "test")
ROOT = Path(__file__).resolve().parents[1]
#: Streams these tests do not need: a pure-Python peer checking every signature falls behind on them.
QUIET = (M.MAVLINK_MSG_ID_HIL_SENSOR, M.MAVLINK_MSG_ID_HIGHRES_IMU, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
         M.MAVLINK_MSG_ID_ESC_STATUS, M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
         M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_VFR_HUD, M.MAVLINK_MSG_ID_ALTITUDE,
         M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS, M.MAVLINK_MSG_ID_GPS_RAW_INT,
         M.MAVLINK_MSG_ID_RAW_RPM, M.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT)  # fmt: skip


def _peer(url: str, sysid: int = 255, key: signing.SigningKey | None = None) -> Any:
    os.environ["MAVLINK20"] = "1"
    conn = mavutil.mavlink_connection(url, source_system=sysid, dialect="common")
    if key is not None:
        signing.configure_connection(conn, key, link_id=3)
    return conn


def _drain(conn: Any) -> None:
    while conn.recv_match(blocking=False) is not None:
        pass


def _recv(conn: Any, mtype: str | list[str], cond: Any = None, timeout: float = 3.0) -> Any:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        m = conn.recv_match(type=mtype, blocking=True, timeout=max(0.01, t_end - time.monotonic()))
        if m is not None and (cond is None or cond(m)):
            return m
    return None


class Hostile:
    """System 66 on its own UDP socket, sending frames signed with ``key`` (None: unsigned)."""

    def __init__(self, sitl_port: int, key: signing.SigningKey | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.3)
        self.dest = ("127.0.0.1", sitl_port)
        self.mav = M.MAVLink(None, 66, 1)
        if key is not None:
            signing.configure(self.mav, key, link_id=9)

    def send(self, msg: Any) -> bytes:
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.sock.sendto(buf, self.dest)
        return bytes(buf)

    def raw(self, frame: bytes) -> None:
        self.sock.sendto(frame, self.dest)

    def heard_from_sitl(self, wait_s: float = 1.0) -> bool:
        """Did a datagram come from the SITL's socket? (Only the SITL's count: an ephemeral port can be
        one some other, earlier client still sends to.)"""
        t_end = time.monotonic() + wait_s
        while time.monotonic() < t_end:
            try:
                _data, addr = self.sock.recvfrom(4096)
            except TimeoutError:
                continue
            if addr == self.dest:
                return True
        return False


def _mission(link: SitlLink) -> list[Any]:
    home = link.sim.scenario.sensors.home
    out = []
    for seq, (cmd, n) in enumerate(((M.MAV_CMD_NAV_TAKEOFF, 0.0), (M.MAV_CMD_NAV_WAYPOINT, 40.0))):
        lat, lon, _ = ned_to_geodetic(np.array([n, 0.0, 0.0]), home)
        out.append(M.MAVLink_mission_item_int_message(1, 1, seq, 6, cmd, 0, 1, 0, 1, 0, math.nan, int(lat * 1e7),
                                                      int(lon * 1e7), 20.0, 0))  # fmt: skip
    return out


def _attack(h: Hostile, link: SitlLink) -> None:
    """Everything system 66 did to the unsigned SITL in issue 14.5."""
    h.send(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
    h.send(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
    h.send(M.MAVLink_mission_count_message(1, 1, 2, 0))
    for it in _mission(link):
        h.send(it)
    h.send(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0))
    h.send(M.MAVLink_param_set_message(1, 1, b"SIM_SPEED", 50.0, M.MAV_PARAM_TYPE_REAL32))
    h.send(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0))


def test_signed_link_rejects_system_66_and_flies_for_the_key_holder() -> None:
    port = free_port()
    with running([udp_to(port)], signing_key=KEY, allow_sim_params=True, true_wind_hz=0.0) as link:
        for mid in QUIET:
            link.streams.set_interval(mid, -1, 0.0)
        sim, ep = link.sim, link.endpoint
        link.params.set(link.params.lookup("NAV_DLL_ACT", -1), 0)  # this GCS sends one HEARTBEAT only
        gcs = _peer(f"udpin:127.0.0.1:{port}", key=KEY)
        hb = _recv(gcs, "HEARTBEAT", timeout=10)
        assert hb is not None and hb._signed, "the SITL's telemetry is signed"
        wait_until(lambda: sim.t > 0.3, 5.0, "a GNSS fix")
        gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
        wait_until(lambda: math.isfinite(link.datalink.last_heartbeat_t), 3.0, "ground link established")
        sitl_port = ep.links[0].transport.port
        # System 66, unsigned, on the ground: nothing it sends is acted on, answered or learned.
        h = Hostile(sitl_port)
        _attack(h, link)
        time.sleep(0.5)
        assert not sim.fc.armed and not sim.fc.mission and link.speed == pytest.approx(4.0)
        assert not h.heard_from_sitl(1.0), "an unsigned sender was answered or learned as a peer"
        assert ("127.0.0.1", h.sock.getsockname()[1]) not in ep.links[0].transport.learned
        # The key holder flies: arm and take off.
        _drain(gcs)
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = _recv(gcs, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_COMPONENT_ARM_DISARM)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED and ack._signed, (
            dict(link.counters), ep.signing_counts(), signing.counts(gcs.mav))
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, math.nan)
        wait_until(lambda: -sim.position[2] > 2.0, 20.0, "airborne")
        # In the air: system 66 again, unsigned and with a wrong key; the vehicle stays armed and up.
        last_hb = link.datalink.last_heartbeat_t
        _attack(h, link)
        _attack(Hostile(sitl_port, OTHER), link)
        time.sleep(0.5)
        assert sim.fc.armed and -sim.position[2] > 2.0 and not sim.fc.mission and link.speed == pytest.approx(4.0)
        # PX4's allowlist let the unsigned HEARTBEATs in, but they prove no ground link.
        assert link.datalink.last_heartbeat_t == last_hb
        c = link.counters
        # 3 attacks x 8 frames; each attack's HEARTBEAT passes PX4's allowlist (accepted, not trusted).
        assert c["rx_unauthenticated"] >= 3 * 7 and c["rx_unsigned_allowed"] >= 3, dict(c)
        assert ep.signing_counts()["bad_signature"] >= 8

        # A forged frame with the key holder's stream id and a far-future time stamp does not lock it out.
        frame = bytearray(gcs.mav.command_long_encode(1, 1, M.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 3, -1, 0, 0, 0, 0)
                          .pack(gcs.mav))  # fmt: skip
        frame[-12:-6] = (2**48 - 1).to_bytes(6, "little")  # time stamp far ahead; signature now wrong
        h.raw(bytes(frame))
        time.sleep(0.2)
        _drain(gcs)
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 2.5, -1, 0, 0, 0, 0)
        ack = _recv(gcs, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_CHANGE_SPEED)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED, "the key holder was locked out"
        # A replayed genuine frame (captured, sent again by someone else) is refused.
        before = c["rx_unauthenticated"]
        genuine = bytes(gcs.mav.command_long_encode(1, 1, M.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
                        .pack(gcs.mav))  # fmt: skip
        gcs.write(genuine)
        wait_until(lambda: sim.fc.mode.value == "AUTO.LAND", 5.0, "land")
        h.raw(genuine)
        wait_until(lambda: c["rx_unauthenticated"] > before, 3.0, "replay refused")
        assert c["handler_errors"] == 0
        gcs.close()


def test_sim_knobs_need_allow_sim_params_and_answers_go_to_the_asker() -> None:
    port = free_port()
    with running([udp_to(port)]) as link:  # no signing, SIM_* locked (the default)
        for mid in QUIET:
            link.streams.set_interval(mid, -1, 0.0)
        a = _peer(f"udpin:127.0.0.1:{port}")
        assert _recv(a, "HEARTBEAT", timeout=10) is not None
        b = _peer(f"udpout:127.0.0.1:{link.endpoint.links[0].transport.port}", sysid=250)
        b.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
        assert _recv(b, "HEARTBEAT", timeout=5) is not None, "a second peer is learned and streamed to"
        # SIM_SPEED=50 over MAVLink: PERMISSION_DENIED, the unchanged value, the speed stays.
        a.mav.param_set_send(1, 1, b"SIM_SPEED", 50.0, M.MAV_PARAM_TYPE_REAL32)
        err = _recv(a, "PARAM_ERROR", lambda m: m.param_id == "SIM_SPEED")
        assert err is not None and err.error == M.MAV_PARAM_ERROR_PERMISSION_DENIED
        echo = _recv(a, "PARAM_VALUE", lambda m: m.param_id == "SIM_SPEED")
        assert echo is not None and echo.param_value == pytest.approx(4.0) and link.speed == pytest.approx(4.0)
        assert link.counters["params_locked"] == 1
        # The SITL's own API is not locked (the operator's command line, tests).
        assert link.params.set(link.params.lookup("SIM_TURB_SCALE", -1), 0.5)
        # B asks: only B is answered (ACK and the requested message); A sees neither.
        for conn in (a, b):
            while conn.recv_match(blocking=False) is not None:
                pass
        b.mav.param_request_read_send(1, 1, b"GF_ACTION", -1)
        b.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0,
                                0, 0)  # fmt: skip
        assert _recv(b, "PARAM_VALUE", lambda m: m.param_id == "GF_ACTION") is not None
        assert _recv(b, "AUTOPILOT_VERSION") is not None
        assert _recv(a, ["PARAM_VALUE", "COMMAND_ACK", "AUTOPILOT_VERSION"], timeout=1.0) is None
        # An accepted set is announced to everyone, as PX4 does.
        a.mav.param_set_send(1, 1, b"MPC_XY_CRUISE", 3.0, M.MAV_PARAM_TYPE_REAL32)
        for conn in (a, b):
            assert _recv(conn, "PARAM_VALUE", lambda m: m.param_id == "MPC_XY_CRUISE") is not None
        a.close()
        b.close()


def test_udp_peer_table_is_bounded_and_expires() -> None:
    t = udp_to(free_port())
    t.MAX_LEARNED = 2
    t.PEER_TIMEOUT_S = 0.5
    with running([t]) as link:
        peers = [_peer(f"udpout:127.0.0.1:{t.port}", sysid=240 + i) for i in range(3)]
        junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for p in peers:
            p.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            time.sleep(0.1)
        # A truncated frame proves nothing: counted, never learned.
        junk.sendto(b"\xfd\x09\x00\x00\x07\xf0\x01\x00\x00\x00" + bytes(4), ("127.0.0.1", t.port))
        wait_until(lambda: t.stats.peers_learned == 3, 3.0, "three peers learned")
        assert len(t.learned) == 2 and t.stats.peers_evicted == 1
        assert ("127.0.0.1", junk.getsockname()[1]) not in t.learned
        wait_until(lambda: not t.learned, 5.0, "silent peers expired")
        assert t.stats.peers_expired == 2 and t.peers == t.configured
        assert link.counters["rx_truncated"] == 1
        for p in peers:
            p.close()
        junk.close()


def test_cli_key_never_in_tlog_summary_or_output(tmp_path: Path) -> None:
    key_file = tmp_path / "k.hex"
    key_file.write_text(KEY.secret.hex() + "\n")
    port = free_port()
    tlog, summary = tmp_path / "f.tlog", tmp_path / "s.json"
    proc = subprocess.Popen([sys.executable, "-m", "windseek.cli", "sitl", "paper-s1", "--speed", "2",
                             "--udp", f"127.0.0.1:{port}", "--signing-key", str(key_file), "--tlog", str(tlog),
                             "--exit-summary", str(summary)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
    try:
        gcs = _peer(f"udpin:127.0.0.1:{port}", key=KEY)
        assert _recv(gcs, "HEARTBEAT", timeout=60) is not None
        # A SETUP_SIGNING (it carries a key) is neither acted on nor logged; an unsigned frame is dropped.
        gcs.mav.setup_signing_send(1, 1, list(OTHER.secret), 0)
        gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
        Hostile(_sitl_port(gcs)).send(
            M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
        # A pymavlink client without MAVLINK20=1 but with the key "signs" MAVLink 1 frames (13 bytes appended):
        # 3 commands and 2 heartbeats, counted as MAVLink 1 while signing is on, not as bad bytes.
        v1 = subprocess.run([sys.executable, "-c", V1_CLIENT, str(_sitl_port(gcs)), KEY.secret.hex()],
                            env={k: v for k, v in os.environ.items() if k != "MAVLINK20"}, capture_output=True,
                            text=True, timeout=60)  # fmt: skip
        assert v1.returncode == 0 and v1.stdout.split() == ["v10", "54", "30"], v1.stdout + v1.stderr
        time.sleep(1.0)
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "signing on" in out and "unauthenticated dropped" in err
    assert "(0 bad, " in err and ", 5 MAVLink 1 while signing is on)" in err, err
    data = tlog.read_bytes()
    for secret in (KEY.secret, OTHER.secret):
        assert secret not in data and secret.hex() not in out + err + summary.read_text()
    frames = mavutil.mavlink_connection(str(tlog), dialect="common")
    ids = set()
    while (m := frames.recv_msg()) is not None:
        ids.add(m.get_msgId())
    assert signing.SETUP_SIGNING_ID not in ids and 0 in ids
    s = json.loads(summary.read_text())
    assert s["signing"]["rx_unauthenticated"] >= 1 and s["signing"]["signed_ok"] >= 1
    assert s["signing"]["rx_mavlink1_signing"] == 5


#: A ground station's script that forgot MAVLINK20=1: pymavlink's MAVLink 1 dialect with signing set up.
V1_CLIENT = """
import sys
from pymavlink import mavutil
conn = mavutil.mavlink_connection("udpout:127.0.0.1:" + sys.argv[1], source_system=254, dialect="common")
conn.setup_signing(bytes.fromhex(sys.argv[2]), sign_outgoing=True)
cmd = conn.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
hb = conn.mav.heartbeat_encode(6, 8, 0, 0, 0)
print(conn.mav.__module__.split(".")[-2], len(cmd.pack(conn.mav)), len(hb.pack(conn.mav)))
for _ in range(3):
    conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
for _ in range(2):
    conn.mav.heartbeat_send(6, 8, 0, 0, 0)
"""


def _sitl_port(conn: Any) -> int:
    """The SITL's UDP port as a udpin peer learned it (the source of the frames it received)."""
    return int(next(iter(conn.clients))[1])


def test_tcp_answers_go_to_the_client_that_asked() -> None:
    from sitl.link import TcpServerTransport

    tcp_port = free_port(socket.SOCK_STREAM)
    with running([TcpServerTransport(tcp_port, "127.0.0.1")]) as link:
        for mid in QUIET:
            link.streams.set_interval(mid, -1, 0.0)
        a, b = (_peer(f"tcp:127.0.0.1:{tcp_port}", sysid=s) for s in (201, 202))
        for conn in (a, b):
            assert _recv(conn, "HEARTBEAT", timeout=10) is not None  # streams go to every client
        wait_until(lambda: len(link.endpoint.links[0].transport.clients) == 2, 5.0, "two clients")
        _drain(a)
        _drain(b)
        a.mav.param_request_read_send(1, 1, b"GF_ACTION", -1)
        assert _recv(a, "PARAM_VALUE", lambda m: m.param_id == "GF_ACTION") is not None
        assert _recv(b, "PARAM_VALUE", timeout=1.0) is None
        a.close()
        b.close()
