"""Hostile input while a mission flies: random bytes, truncated frames, bad CRCs, unknown message
ids, NaN and out-of-range setpoints and mission items, on both the UDP and a TCP link. The
mission must complete, every bad input must be counted and, where the protocol has an answer
(a stray MISSION_ITEM_INT, a NaN command), answered."""

from __future__ import annotations

import math
import os
import random
import socket
import struct
import time

import numpy as np
from link_support import free_port, running, udp_to, wait_until
from pymavlink import mavutil

from sitl.link import TcpServerTransport
from sitl.world.sensors import ned_to_geodetic
from wire.dialect import mavlink as M  # noqa: N812


def _frame(msg: object, seq: int = 0) -> bytes:
    enc = M.MAVLink(None, 250, 1)
    enc.seq = seq
    return msg.pack(enc)


def test_hostile_input_while_mission_flies() -> None:
    port, tcp_port = free_port(), free_port(socket.SOCK_STREAM)
    with running([udp_to(port), TcpServerTransport(tcp_port, "127.0.0.1")]) as link:
        os.environ["MAVLINK20"] = "1"
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
        assert gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
        sim = link.sim
        wait_until(lambda: sim.t > 0.3, 5.0, "first GNSS fix")
        home = sim.scenario.sensors.home

        def item(seq: int, cmd: int, n: float = 0.0, e: float = 0.0, alt: float = 3.0, frame: int = 6) -> object:
            lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), home)
            return M.MAVLink_mission_item_int_message(1, 1, seq, frame, cmd, 0, 1, 0.0, 0.8, 0.0, math.nan,
                                                      int(lat * 1e7), int(lon * 1e7), alt, 0)  # fmt: skip

        plan = [item(0, M.MAV_CMD_NAV_TAKEOFF), item(1, M.MAV_CMD_NAV_WAYPOINT, 6.0, 0.0),
                item(2, M.MAV_CMD_NAV_WAYPOINT, 6.0, 5.0), item(3, M.MAV_CMD_NAV_LAND, 6.0, 5.0)]  # fmt: skip
        gcs.mav.mission_count_send(1, 1, len(plan), 0)
        while True:
            m = gcs.recv_match(type=["MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=3)
            assert m is not None
            if m.get_type() == "MISSION_ACK":
                assert m.type == M.MAV_MISSION_ACCEPTED
                break
            gcs.mav.send(plan[m.seq])
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
        wait_until(lambda: sim.fc.armed and sim.fc.mode.value == "AUTO.MISSION", 5.0, "mission started")

        rng = random.Random(5)
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sitl_port = link.endpoint.links[0].transport.port
        tcp = socket.create_connection(("127.0.0.1", tcp_port))
        nan_sp = M.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0b0000_1101_1111_1000, math.nan, 0, -3,
                                                                 0, 0, 0, 0, 0, 0, 0, 0)  # fmt: skip
        far_sp = M.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0b0000_1100_0000_0111, 0, 0, 0,
                                                                 500.0, 0, 0, 0, 0, 0, 0, 0)  # fmt: skip
        bad_att = M.MAVLink_set_attitude_target_message(0, 1, 1, 0, [math.nan, 0, 0, 0], 0, 0, 0, 2.0)
        stray_item = M.MAVLink_mission_item_int_message(1, 1, 0, 6, M.MAV_CMD_NAV_WAYPOINT, 0, 1, math.nan, 0, 0, 0,
                                                        950_000_000, 0, math.nan, 0)  # fmt: skip
        nan_cmd = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_REPOSITION, 0, -1, 0, 0, math.nan,
                                                 1e9, 1e9, math.inf)  # fmt: skip
        good_hb = _frame(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        sent = {"garbage": 0, "truncated": 0, "bad_crc": 0, "unknown": 0, "setpoints": 0}
        t_end = time.monotonic() + 40.0
        k = 0
        while time.monotonic() < t_end and not (sim.fc.mission_index >= len(plan) and not sim.fc.armed):
            k += 1
            junk = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300)))
            trunc = good_hb[: rng.randint(3, len(good_hb) - 1)]
            crc = bytearray(_frame(nan_sp, k % 256))
            crc[-1] ^= 0x5A
            unknown = bytearray(good_hb)
            unknown[7:10] = struct.pack("<I", 60_123)[:3]  # msgid 60123: no such message
            for target in (lambda b: udp.sendto(b, ("127.0.0.1", sitl_port)), tcp.sendall):
                target(junk)
                target(trunc)
                target(bytes(crc))
                target(bytes(unknown))
            sent["garbage"] += 1
            sent["truncated"] += 1
            sent["bad_crc"] += 1
            sent["unknown"] += 1
            for msg in (nan_sp, far_sp, bad_att):
                udp.sendto(_frame(msg, k % 256), ("127.0.0.1", sitl_port))
                sent["setpoints"] += 1
            if k % 10 == 0:
                gcs.mav.send(stray_item)
                gcs.mav.send(nan_cmd)
            time.sleep(0.02)
        udp.close()
        tcp.close()
        # The mission completes: every item reached, landed and disarmed near the last waypoint.
        wait_until(lambda: not sim.fc.armed, 20.0, "mission complete and disarmed")
        assert sim.fc.mission_index == len(plan)
        assert np.allclose(sim.position[:2], [6.0, 5.0], atol=1.5) and not sim.crashed
        c = link.counters
        assert c["rx_bad"] >= sent["garbage"]
        assert c["rx_bad_crc"] > 0 and c["rx_unknown_id"] > 0 and c["rx_truncated"] > 0
        assert c["setpoints_rejected"] >= sent["setpoints"] * 0.9  # UDP on localhost: nearly all arrive
        assert c["mission_errors"] > 0 and c["commands_refused"] > 0
        assert c["handler_errors"] == 0
        # Answers where the protocol has one.
        acks = [gcs.recv_match(type=["MISSION_ACK", "COMMAND_ACK"], blocking=True, timeout=1) for _ in range(2)]
        assert any(a is not None for a in acks)
        gcs.close()
