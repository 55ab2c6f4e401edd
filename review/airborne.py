"""Is the vehicle in the air? Arming is not flight: the evidence a reader's in-air state must carry.

The readers take the in-air state from the log's landed state (EXTENDED_SYS_STATE, PX4's
vehicle_land_detected, ArduPilot's STAT.isFlying) and, without one, from arming. Arming alone says
the motors may turn, not that the vehicle left the ground (an ArduSub tlog armed for 16 s at a depth
within +-0.3 m used to read "16.0 s airborne"). :func:`judge_airborne` therefore

- drops every in-air interval of a vehicle type that does not fly (a submarine, a rover, a boat, an
  antenna tracker), whatever the source, and
- keeps an armed interval (in-air state from arming) only when the position shows a climb of at
  least :data:`MIN_CLIMB_M` above where the vehicle armed; a log without position shows none.

The landed state of a flying vehicle is evidence enough and is kept as it is.
"""

from __future__ import annotations

import numpy as np

from review.flight import FlightData
from review.vehicle_info import NON_FLYING_TYPES

#: Climb [m] above the height at arming that an armed interval needs to count as flight: well above
#: the noise of a barometer or GNSS height at rest (about 0.3 m) and of a submarine's depth hold.
MIN_CLIMB_M = 1.0


def _climb_m(fd: FlightData, t0: float, t1: float) -> float:
    """Largest height [m] above the first position sample of [t0, t1] (NED: height = -down); NaN without
    position samples in that interval."""
    p = fd.position.between(t0, t1)
    if not len(p):
        return float("nan")
    up = -np.asarray(p.v[:, 2], dtype=float)
    up = up[np.isfinite(up)]
    return float(np.max(up) - up[0]) if len(up) else float("nan")


def judge_airborne(fd: FlightData) -> None:
    """Drop in-air intervals without evidence of flight (see the module docstring); says why in
    ``fd.notes`` and in ``fd.not_airborne`` (the summary's reason for no wind figure)."""
    segs = fd.airborne_segments()
    if not segs:
        return
    total = sum(b - a for a, b in segs)
    if fd.vehicle_type.lower() in NON_FLYING_TYPES:
        fd.not_airborne = f"the vehicle is a {fd.vehicle_type}, which does not fly"
        fd.notes.append(f"{fd.not_airborne}: {total:.1f} s in-air state from {fd.sources.get('in_air')} "
                        "not counted airborne")  # fmt: skip
        fd.in_air = [(a, False) for a, _ in segs]  # the rrd's in-air plot says so too
        return
    if not fd.sources.get("in_air", "").endswith("(armed)"):
        return  # a landed state: the autopilot's own flight evidence
    kept, dropped = 0, 0.0
    states: list[tuple[float, bool]] = []
    for a, b in segs:
        if _climb_m(fd, a, b) >= MIN_CLIMB_M:
            kept += 1
            states += [(a, True), (b, False)]
        else:
            dropped += b - a
            states.append((a, False))
    if dropped:
        why = "no position in the log" if not len(fd.position) else f"no climb of {MIN_CLIMB_M:g} m or more"
        fd.notes.append(f"{dropped:.1f} s armed with {why}: armed is not airborne, not counted")
        if not kept:
            fd.not_airborne = f"armed, but {why} shows a flight"
    fd.in_air = states


__all__ = ["MIN_CLIMB_M", "judge_airborne"]
