"""Finding the autopilot on a MAVSDK (4.x, ``mavsdk.asyncio``) connection: one rule for the
MAVSDK runner and the end-to-end tests."""

from __future__ import annotations

import time
from typing import Any


async def find_autopilot(sdk: Any, timeout_s: float) -> Any:
    """The autopilot system of ``sdk`` (a connected ``mavsdk.asyncio.Mavsdk``), or None after
    ``timeout_s`` wall seconds.

    ``first_autopilot`` alone was seen (rarely, under load) to miss an autopilot already
    discovered, so the discovered systems are polled as well.
    """
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        drone = await sdk.first_autopilot(1.0)
        if drone is not None:
            return drone
        for system in await sdk.get_systems():
            if await system.has_autopilot() and await system.is_connected():
                return system
    return None
