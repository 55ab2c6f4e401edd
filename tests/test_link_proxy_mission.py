"""Mission transfers on a bad link: MAVSDK's mission plugin (the MAVLink mission protocol) through the
link proxy to the in-process SITL, at 30 % loss each way and with duplicates and reordering; and the
SITL's side of the protocol against a pymavlink peer that duplicates an item.

Found with the proxy: the SITL answered a duplicated MISSION_ITEM_INT with another MISSION_REQUEST_INT;
each extra request brought another duplicate item, MAVSDK counted every repeated request as a retry
and gave up after five (TIMEOUT) at 20 % duplication. A duplicate is now ignored, as PX4 does.
"""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from link_support import free_port, running, scenario, udp_to
from pymavlink import mavutil

import sitl.link.mission_protocol as mission_protocol
from wire.dialect import mavlink as M  # noqa: N812
from wire.proxy import Faults, LinkProxy

LOSS = Faults(loss=0.3)
DUP_REORDER = Faults(duplicate=0.2, reorder=0.2, latency_s=0.005, jitter_s=0.005)


def test_a_duplicated_item_is_ignored_not_answered(monkeypatch: pytest.MonkeyPatch) -> None:
    """A duplicate MISSION_ITEM_INT brings no second request (only the re-request timer would)."""
    monkeypatch.setattr(mission_protocol, "REQUEST_TIMEOUT_S", 30.0)  # no timer re-request in this test
    port = free_port()
    with running([udp_to(port)], scenario()) as link:
        os.environ["MAVLINK20"] = "1"
        peer = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
        try:
            assert peer.recv_match(type="HEARTBEAT", blocking=True, timeout=10) is not None
            home = link.sim.scenario.sensors.home
            items = [M.MAVLink_mission_item_int_message(1, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                        M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0.5, 0, 0,
                                                        int(home.lat_deg * 1e7) + 100 * seq, int(home.lon_deg * 1e7),
                                                        3.0)  # fmt: skip
                     for seq in range(3)]
            peer.mav.mission_count_send(1, 1, 3, 0)
            requests: list[int] = []

            # (10 s for an answer: it comes in milliseconds, but beside another e2e test on 2 cores 3 s was not enough)
            def until(pred: Callable[[Any], bool], timeout: float = 10.0) -> Any:
                t_end = time.monotonic() + timeout
                while time.monotonic() < t_end:
                    m = peer.recv_match(type=["MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=0.1)
                    if m is not None:
                        if m.get_type() == "MISSION_REQUEST_INT":
                            requests.append(m.seq)
                        if pred(m):
                            return m
                return None

            assert until(lambda m: m.get_type() == "MISSION_REQUEST_INT" and m.seq == 0) is not None
            peer.mav.send(items[0])
            peer.mav.send(items[0])  # the duplicate
            assert until(lambda m: m.get_type() == "MISSION_REQUEST_INT" and m.seq == 1) is not None
            until(lambda m: False, 0.5)
            assert requests == [0, 1]  # nothing more: no request for the duplicate
            peer.mav.send(items[1])
            assert until(lambda m: m.get_type() == "MISSION_REQUEST_INT" and m.seq == 2) is not None
            peer.mav.send(items[1])  # a late duplicate, then the last item
            peer.mav.send(items[2])
            ack = until(lambda m: m.get_type() == "MISSION_ACK")
            assert ack is not None and ack.type == M.MAV_MISSION_ACCEPTED
            assert requests == [0, 1, 2]
            assert len(link.sim.fc.mission) == 3 and link.counters["mission_duplicates"] == 2
        finally:
            peer.close()


# ---------------------------------------------------------------------- mission upload
async def _with_retries(op: Callable[[], Any], check: Callable[[], None], attempts: int = 5) -> int:
    """Run a MAVSDK mission transfer; one that timed out is started again, as an application must (MAVSDK
    and the autopilot each re-send a lost message 5 times, then give up; MAVSDK says BUSY until it has
    dropped the failed transfer). ``check()`` after every failure (the autopilot never holds a half
    plan). Returns the attempts it took."""
    from mavsdk.plugins.mission import MissionError

    for attempt in range(1, attempts + 1):
        try:
            await asyncio.wait_for(op(), 60.0)
            return attempt
        except MissionError as e:
            print(f"attempt {attempt}: {e}")
            check()
            if e.result.name not in ("TIMEOUT", "BUSY") or attempt == attempts:
                raise
            await asyncio.sleep(1.0)
    return attempts


@pytest.mark.e2e
@pytest.mark.asyncio
@pytest.mark.parametrize("faults", [LOSS, DUP_REORDER], ids=["loss-30", "dup-reorder"])
async def test_mission_upload_through_a_bad_link(faults: Faults) -> None:
    pytest.importorskip("mavsdk")
    from link_support import autopilot
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mission import MissionAsync
    from mavsdk.plugins.mission import MissionItem, MissionPlan

    from sitl.link import UdpTransport
    from sitl.world.sensors import ned_to_geodetic

    mport = free_port()
    proxy = LinkProxy("udpin:127.0.0.1:0", f"udpout:127.0.0.1:{mport}", faults, seed=5).start()
    wps = [(0.0, 0.0, 3.0), *((5.0 * i, (-2.0) ** i, 3.0 + 0.5 * i) for i in range(1, 8))]
    try:
        with running([UdpTransport([("127.0.0.1", proxy.a.port)], ("127.0.0.1", 0))], scenario(), 1.0) as link:
            home = link.sim.scenario.sensors.home
            items = []
            for n, e, alt in wps:
                lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), home)
                items.append(MissionItem(latitude_deg=lat, longitude_deg=lon, relative_altitude_m=alt,
                                         is_fly_through=False, acceptance_radius_m=0.5))  # fmt: skip

            def held() -> list[Any]:
                return [it for it in link.sim.fc.mission if it.kind.name == "WAYPOINT"]

            def whole_or_nothing() -> None:
                assert len(held()) in (0, len(wps)), "a half-transferred plan was installed"

            async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
                drone = await autopilot(sdk, f"udpin://127.0.0.1:{mport}", 20.0)
                assert drone is not None
                mission = MissionAsync(drone)
                up = await _with_retries(lambda: mission.upload_mission(MissionPlan(items)), whole_or_nothing)
                # What the autopilot holds: every waypoint, in order, where it was planned.
                assert len(held()) == len(wps)
                for it, (n, e, alt) in zip(held(), wps, strict=True):
                    assert it.position_ned[0:2] == pytest.approx([n, e], abs=0.05)
                    assert -it.position_ned[2] == pytest.approx(alt, abs=0.05)
                got: list[Any] = []

                async def download() -> None:
                    got[:] = (await mission.download_mission()).mission_items

                down = await _with_retries(download, lambda: None)
                flat = [v for i in got for v in (i.latitude_deg, i.longitude_deg, i.relative_altitude_m)]
                want = [v for i in items for v in (i.latitude_deg, i.longitude_deg, i.relative_altitude_m)]
                assert flat == pytest.approx(want, abs=1e-6)
        assert link.counters["handler_errors"] == 0
    finally:
        rep = proxy.report()
        proxy.stop()
    print(f"upload in {up} attempt(s), download in {down}; proxy {rep}")
    key = "dropped_loss" if faults.loss else "duplicated"
    assert all(rep[d][key] > 0 for d in ("a->b", "b->a")), rep  # the faults did hit both ways
