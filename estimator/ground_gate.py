"""When to feed the wind estimator around the ground: one rule for every adapter.

Ground contact forces are not in the estimator's force model, and the ``uncalibrated``
preset's force-scale state would absorb them (seen: scale 0.96 +- 0.002 with the exact model,
a 5 m/s wind read as 7 m/s). So the filter takes no sample while the vehicle is on the ground
and cold-starts at lift-off; a filter that already flew is replaced at the next lift-off, not
at touchdown, so its figures stay readable after landing. No I/O: the adapters say whether the
vehicle is on the ground (the simulator's land detector, MAVLink EXTENDED_SYS_STATE).
"""

from __future__ import annotations

from typing import Literal


class GroundGate:
    """Pause on the ground, replace a flown filter at the next lift-off."""

    def __init__(self) -> None:
        self._fed = False  # the current filter has had samples
        self._grounded = False  # samples withheld since then (the vehicle on the ground)

    def admit(self, on_ground: bool) -> Literal["pause", "restart", "feed"]:
        """What to do with the samples that arrive now: ``pause`` (drop them), ``restart``
        (replace the filter with a fresh one, then feed it), or ``feed``."""
        if on_ground:
            self._grounded = True
            return "pause"
        restart = self._grounded and self._fed
        self._grounded = False
        self._fed = True
        return "restart" if restart else "feed"
