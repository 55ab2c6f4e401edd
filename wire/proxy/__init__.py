"""A MAVLink link-fault proxy: seeded loss, bursts, duplication, reordering, latency, jitter, bandwidth
limits and cuts between two endpoints (``windseek link-proxy``; the tests' own faulty links).

- ``faults``: the pure, seeded fault model (:class:`Faults`, :class:`Channel`, :class:`Cut`).
- ``framing``: MAVLink frames out of a byte stream or a datagram (header only).
- ``endpoints``: UDP and TCP ends (listen / send first).
- ``proxy``: :class:`LinkProxy`, the I/O thread around the model (start/stop, cut/restore, report).
"""

from wire.proxy.faults import Channel, Cut, Faults
from wire.proxy.proxy import TRIGGERS, LinkProxy

__all__ = ["TRIGGERS", "Channel", "Cut", "Faults", "LinkProxy"]
