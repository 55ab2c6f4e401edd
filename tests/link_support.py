"""Shared helpers of the MAVLink link tests: a fast test scenario, free ports, a SITL thread."""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import time
from collections.abc import AsyncIterator, Callable, Iterator
from typing import Any

from mission.runners.autopilot import find_autopilot
from sitl.link import SitlLink, UdpTransport
from sitl.link.transports import Transport
from sitl.scenario import Scenario, parse_scenario
from sitl.simulation import Simulation
from wire.dialect import mavlink as M  # noqa: N812

#: Speed factor of the end-to-end tests: fast, but every stream keeps its rate on 2 shared cores.
SPEED = 4.0


def scenario(**extra: Any) -> Scenario:
    """Ground start in a light steady wind, low take-off/RTL altitudes so flights are short."""
    data: dict[str, Any] = {
        "name": "link-test",
        "duration_s": 600.0,
        "seed": 7,
        "wind": {"velocity_ned": [-2.0, 0.0, 0.0]},
        "route": {"takeoff_altitude_m": 3.0, "cruise_speed_m_s": 4.0},
        "flight": {"rtl_altitude_m": 4.0, "land_speed_m_s": 1.5, "disarm_after_land_s": 0.5},
    }
    data.update(extra)
    return parse_scenario(data)


#: Ports handed out by :func:`free_port`: below Linux's ephemeral range (32768-60999), so no socket bound
#: to port 0 (a SITL's, MAVSDK's, another test's) can take one between the check and the test's own bind.
#: Each pytest-xdist worker gets its own slice, and a process starts at an offset of its pid within it.
PORT_BASE, PORT_SPAN = 20000, 12000
_next_port = [0]


def _worker_slice() -> tuple[int, int]:
    w = os.environ.get("PYTEST_XDIST_WORKER", "")
    n = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1))
    i = int(w[2:]) if w.startswith("gw") and w[2:].isdigit() else 0
    span = PORT_SPAN // n
    return PORT_BASE + i * span, span


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port that is free now for ``kind`` and for UDP and TCP alike, outside the ephemeral range (never
    14540/14550): successive calls in one process never repeat a port within its slice."""
    base, span = _worker_slice()
    if not _next_port[0]:
        _next_port[0] = os.getpid() * 7919 % span
    for _ in range(span):
        port = base + _next_port[0] % span
        _next_port[0] += 1
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
                u.bind(("127.0.0.1", port))
                with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as t:
                    t.bind(("127.0.0.1", port))
        except OSError:
            continue
        return port
    raise RuntimeError(f"no free port in {base}-{base + span - 1}")


@contextlib.contextmanager
def running(transports: list[Transport], sc: Scenario | None = None, speed: float = SPEED,
            **kw: Any) -> Iterator[SitlLink]:  # fmt: skip
    """A SitlLink serving in a background thread for the duration of the block."""
    sim = Simulation(sc or scenario(), autostart_route=False)
    link = SitlLink(sim, transports, speed=speed, **kw)
    link.start()
    try:
        yield link
    finally:
        link.close()
    assert link.error is None, f"the SITL loop died: {link.error!r}"


def udp_to(port: int) -> UdpTransport:
    return UdpTransport([("127.0.0.1", port)], ("127.0.0.1", 0))


#: The high-rate streams a ground-station test turns off, so that its socket carries what it asked for.
HIGH_RATE_STREAMS = (M.MAVLINK_MSG_ID_HIL_SENSOR, M.MAVLINK_MSG_ID_HIGHRES_IMU, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
                     M.MAVLINK_MSG_ID_ESC_STATUS, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_ATTITUDE)


@contextlib.contextmanager
def quiet_running(port: int) -> Iterator[SitlLink]:
    """A SITL streaming to UDP ``port`` on localhost without its high-rate streams (a ground-station
    test's view: heartbeats, status and the answers to its requests)."""
    with running([udp_to(port)]) as link:
        for mid in HIGH_RATE_STREAMS:
            link.streams.set_interval(mid, -1, 0.0)
        yield link


async def first(agen: AsyncIterator, pred: Callable[[Any], bool], timeout: float, what: str = "") -> Any:
    """First item of an async stream that satisfies ``pred``; fails the test after ``timeout`` s."""

    async def _scan() -> Any:
        async for item in agen:
            if pred(item):
                return item
        return None

    try:
        return await asyncio.wait_for(_scan(), timeout)
    except TimeoutError:
        raise AssertionError(f"timed out after {timeout} s waiting for {what or pred}") from None


async def autopilot(sdk: Any, url: str, timeout: float = 15.0) -> Any:
    """Connect ``sdk`` (a ``mavsdk.asyncio.Mavsdk``) to ``url`` and return the autopilot system
    (the runner's rule, ``mission.runners.autopilot``); None after ``timeout`` s."""
    await sdk.add_any_connection(url)
    return await find_autopilot(sdk, timeout)


def wait_until(pred: Callable[[], bool], timeout: float, what: str = "") -> None:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if pred():
            return
        time.sleep(0.01)
    raise AssertionError(f"timed out after {timeout} s waiting for {what or pred}")
