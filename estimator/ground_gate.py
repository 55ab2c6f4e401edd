"""When to feed the wind estimator around the ground: one rule for every adapter.

Ground contact forces are not in the estimator's force model, and the ``uncalibrated``
preset's force-scale state would absorb them (seen: scale 0.96 +- 0.002 with the exact model,
a 5 m/s wind read as 7 m/s). So the filter takes no sample while the vehicle is on the ground
and cold-starts at lift-off; a filter that already flew is replaced at the next lift-off, not
at touchdown, so its figures stay readable after landing. No I/O: the adapters say whether the
vehicle is on the ground (the simulator's contact flag, MAVLink EXTENDED_SYS_STATE through
:func:`withheld`).

Over MAVLink the landed state alone opens the gate too early: PX4 reports "not landed" (and
TAKEOFF) once its land detector sees the thrust rise, while the rotors are still spinning up
with the vehicle on the ground, and those samples were read as an updraft (a vertical wind of
-98 m/s NED two seconds after a ``windseek demo`` take-off, still -5 m/s after 20 s). So after
the vehicle was on the ground, :class:`LiftOff` holds the gate until it has climbed
``clear_m`` above its height on the ground (from the chosen position message), or, in a stream
without a height, for ``max_wait_s`` of autopilot time.

Over MAVLink the filter also stops at the start of a landing (MAV_LANDED_STATE_LANDING):
EXTENDED_SYS_STATE arrives a fraction of a second after touchdown, and the ground-contact
samples of that interval were read as an updraft (the last estimate before the pause: a
vertical wind of -8 to -10 m/s NED through MAVProxy and in ``windseek demo``).
"""

from __future__ import annotations

import math
from typing import Literal

#: MAV_LANDED_STATE values used here (MAVLink common.xml).
LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_LANDING = 1, 2, 4


def withheld(landed_state: int | None) -> bool:
    """True when a MAVLink MAV_LANDED_STATE (EXTENDED_SYS_STATE; None: never reported) says the
    filter must take no samples: on the ground or landing."""
    return landed_state in (LANDED_ON_GROUND, LANDED_LANDING)


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


class LiftOff:
    """Hold the gate after the ground until the vehicle has climbed clear of it.

    :meth:`update` with the autopilot's time (s), whether it says the vehicle is on the ground,
    and its height (m, up; None when the stream has none) at every message; :attr:`clear` says
    whether samples may flow. A stream that starts in the air is clear from the start."""

    def __init__(self, clear_m: float = 0.5, max_wait_s: float = 5.0) -> None:
        self.clear_m = clear_m
        self.max_wait_s = max_wait_s
        self.clear = True
        self._ground_up: float | None = None  # height on the ground, m up (None: not known)
        self._since: float | None = None  # time the landed state last left the ground, s

    def update(self, t: float, on_ground: bool, up: float | None) -> None:
        if on_ground:
            self.clear, self._since = False, None
            if up is not None:
                self._ground_up = up
            return
        if self.clear:
            return
        if self._since is None or not math.isfinite(self._since):
            self._since = t
        climbed = up is not None and self._ground_up is not None and up - self._ground_up >= self.clear_m
        if climbed or t - self._since >= self.max_wait_s or t < self._since:
            self.clear, self._ground_up = True, None
