"""``windseek sitl --forward``: PX4's ``MAV_X_FORWARD`` on every link.

A frame received on one link that is not addressed to the autopilot (system 1, component 1) goes
out unchanged on every other link and to the other peers of the same UDP link, so the mission and a
ground station see the estimator's WIND_COV and the mission's status. Runs in the link's thread.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from sitl.link.endpoint import COMPONENT_ID, SYSTEM_ID, Link
from sitl.link.transports import UdpTransport

if TYPE_CHECKING:
    from sitl.link.runner import SitlLink


def addressed_to_autopilot(msg: Any) -> bool:
    """True for a message addressed to system 1, component 1 (or to system 1 with no component)."""
    ts = getattr(msg, "target_system", None)
    if ts is None or ts != SYSTEM_ID:
        return False
    return getattr(msg, "target_component", COMPONENT_ID) in (COMPONENT_ID,)


class Forwarder:
    """PX4-style forwarding of frames not addressed to the autopilot to every other link and peer."""

    def __init__(self, link: SitlLink) -> None:
        self.link = link
        self.forwarded = 0
        link.endpoint.rx_hooks.append(self.on_message)

    def on_message(self, msg: Any, src: Link) -> None:
        if addressed_to_autopilot(msg):
            return
        frame = msg.get_msgbuf()
        for lk in self.link.endpoint.links:
            t = lk.transport
            if lk is not src:
                t.write(frame)
            elif isinstance(t, UdpTransport) and src.rx_source is not None:
                t.write_except(frame, src.rx_source)
        self.forwarded += 1
        self.link.counters["forwarded"] += 1


__all__ = ["Forwarder", "addressed_to_autopilot"]
