"""When to feed the wind estimator around the ground: one rule for every adapter.

Ground contact forces are not in the estimator's force model, and the ``uncalibrated``
preset's force-scale state would absorb them (seen: scale 0.96 +- 0.002 with the exact model,
a 5 m/s wind read as 7 m/s). So the filter takes no sample while the vehicle is on the ground
and cold-starts at lift-off; a filter that already flew is replaced at the next lift-off, not
at touchdown, so its figures stay readable after landing. No I/O: the adapters say whether the
vehicle is on the ground (the simulator's contact flag, MAVLink EXTENDED_SYS_STATE through
:func:`withheld`).

Over MAVLink the filter also stops at the start of a landing (MAV_LANDED_STATE_LANDING):
EXTENDED_SYS_STATE arrives a fraction of a second after touchdown, and the ground-contact
samples of that interval were read as an updraft (the last estimate before the pause: a
vertical wind of -8 to -10 m/s NED through MAVProxy and in ``windseek demo``).
"""

from __future__ import annotations

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
