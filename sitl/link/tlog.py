"""``windseek sitl --tlog PATH``: every MAVLink frame the SITL sends and receives, as a ``.tlog``.

The standard format: per frame an 8-byte big-endian time stamp in microseconds, then the frame as
on the wire. The time stamp is **wall-clock UNIX time** (what MAVProxy and QGroundControl write,
so MAVExplorer and ``mavlogdump.py`` show real dates); the simulation time is inside the messages
(``time_boot_ms`` / ``time_usec``). Frames sent to several links are logged once. Runs in the
link's own thread (the endpoint's ``tx_hooks`` and ``rx_hooks``), so it needs no lock.
"""

from __future__ import annotations

import struct
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from sitl.link.endpoint import Link
    from sitl.link.runner import SitlLink


class TlogWriter:
    """Writes every frame the link sends and receives to a ``.tlog`` (see the module docstring)."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self.frames = 0

    def write(self, frame: bytes, t_unix_s: float | None = None) -> None:
        if self._f.closed:
            return
        ts = int((time.time() if t_unix_s is None else t_unix_s) * 1e6)
        self._f.write(struct.pack(">Q", ts) + bytes(frame))
        self.frames += 1

    def attach(self, link: SitlLink) -> TlogWriter:
        ep = link.endpoint

        def received(msg: Any, lk: Link) -> None:  # msg: a parsed pymavlink message
            self.write(msg.get_msgbuf())

        ep.tx_hooks.append(self.write)  # every outgoing frame is packed exactly once, in Endpoint.encode
        ep.rx_hooks.append(received)
        return self

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()


__all__ = ["TlogWriter"]
