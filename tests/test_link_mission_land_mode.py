"""The mode on the wire through a mission's LAND item (issue 31, finding 4).

PX4 flies a mission's NAV_LAND item inside Mission mode (navigator's MissionBase handles NAV_CMD_LAND;
nav_state stays AUTO_MISSION), and the SITL reports it so. It used to send one HEARTBEAT in AUTO.LAND
at the land item, built before the mission-landing state was set, then AUTO.MISSION 70 ms later
(MAVProxy printed "Mode LAND", then "Mode MISSION"). A pymavlink ground station on a real UDP socket
records every autopilot HEARTBEAT from the mission's start until the vehicle disarms on the ground.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
from link_support import free_port, quiet_running, wait_until
from pymavlink import mavutil

from sitl.world.sensors import ned_to_geodetic
from wire import px4_modes
from wire.dialect import mavlink as M  # noqa: N812


def test_mission_land_item_stays_in_mission_mode_without_flip_flop() -> None:
    port = free_port()
    with quiet_running(port) as link:
        os.environ["MAVLINK20"] = "1"
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
        assert gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
        sim = link.sim
        wait_until(lambda: sim.t > 0.3, 5.0, "first GNSS fix")
        home = sim.scenario.sensors.home

        def item(seq: int, cmd: int, n: float = 0.0, e: float = 0.0) -> object:
            lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), home)
            return M.MAVLink_mission_item_int_message(1, 1, seq, 6, cmd, 0, 1, 0.0, 0.8, 0.0, math.nan,
                                                      int(lat * 1e7), int(lon * 1e7), 3.0, 0)  # fmt: skip

        plan = [item(0, M.MAV_CMD_NAV_TAKEOFF), item(1, M.MAV_CMD_NAV_WAYPOINT, 4.0, 0.0),
                item(2, M.MAV_CMD_NAV_LAND, 4.0, 0.0)]  # fmt: skip
        gcs.mav.mission_count_send(1, 1, len(plan), 0)
        while (m := gcs.recv_match(type=["MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=3)) is not None:
            if m.get_type() == "MISSION_ACK":
                assert m.type == M.MAV_MISSION_ACCEPTED
                break
            gcs.mav.send(plan[m.seq])
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
        modes: list[tuple[str, bool]] = []  # (mode on the wire, armed) of every autopilot HEARTBEAT
        reached: list[int] = []
        t_end = time.monotonic() + 60.0
        while time.monotonic() < t_end and not (modes and not modes[-1][1] and 2 in reached):
            m = gcs.recv_match(type=["HEARTBEAT", "MISSION_ITEM_REACHED"], blocking=True, timeout=1)
            if m is None or m.get_srcSystem() != 1:
                continue
            if m.get_type() == "MISSION_ITEM_REACHED":
                reached.append(m.seq)
            elif m.get_srcComponent() == 1:
                modes.append((px4_modes.name(m.custom_mode), bool(m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)))
    assert 2 in reached, f"the land item was not flown to the ground: reached {reached}"
    flown = [mode for mode, armed in modes if armed]
    assert "AUTO.MISSION" in flown and "AUTO.LAND" not in [mode for mode, _ in modes], modes
    runs = [mode for k, (mode, _) in enumerate(modes) if k == 0 or mode != modes[k - 1][0]]
    assert len(runs) == len(set(runs)), f"the mode went back and forth: {runs}"
    assert modes[-1] == ("AUTO.MISSION", False), modes[-1]  # PX4 stays in Mission after the disarm
