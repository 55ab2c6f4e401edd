"""Flight phases from what any recorder sees: the autopilot's mode and arming, the strategy's states
and the declaration.

:class:`PhaseTracker` turns those events into the mission phase (a lane of the state timeline:
on ground, armed, take-off, hover, search, verify, descend, landing, landed) and into markers for
the time series: take-off, search start, landing and landed (``phase``), the start of each
verification sweep (``verify``) and the declaration (``declared``). Mode names are matched loosely
(PX4's ``AUTO.TAKEOFF`` or pymavlink's ``TAKEOFF``, ``OFFBOARD``, ``AUTO.LAND`` or ``LAND``, ``RTL``),
so simulated runs and reviewed logs get the same phases. Times are vehicle seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

MARKER_KINDS = ("phase", "verify", "declared")


@dataclass
class Marker:
    """A moment to mark on every time series: vehicle time [s], kind (:data:`MARKER_KINDS`), label."""

    t: float
    kind: str
    label: str


@dataclass
class PhaseTracker:
    """The mission phase and its markers (see the module docstring); every ``on_*`` returns the new
    phase when it changed, else None."""

    phase: str = "on ground"
    markers: list[Marker] = field(default_factory=list)
    verifications: list[list[float]] = field(default_factory=list)  # [t_start, t_end (NaN while on)]
    t_arm: float = math.nan
    t_takeoff: float = math.nan
    t_search: float = math.nan
    t_declared: float = math.nan
    t_landing: float = math.nan
    t_disarm: float = math.nan
    armed: bool = False
    flown: bool = False
    searching: bool = False
    declared: bool = False
    state: str = ""
    mode: str = ""

    def _to(self, phase: str) -> str | None:
        if phase == self.phase:
            return None
        self.phase = phase
        return phase

    def _mark(self, t: float, kind: str, label: str) -> None:
        self.markers.append(Marker(float(t), kind, label))

    def _flying_phase(self) -> str:
        """The phase while airborne and not taking off or landing."""
        if self.declared:
            return "descend"
        if self.searching:
            return "verify" if self.state == "verify" else "search"
        return "hover"

    # ------------------------------------------------------------------ events
    def on_armed(self, t: float, armed: bool) -> str | None:
        if armed == self.armed:
            return None
        self.armed = armed
        if armed:
            if math.isnan(self.t_arm):
                self.t_arm = t
            self.flown = True
            # The mode may have switched to take-off in the same tick, before the arming was seen.
            return self._to("armed") if self.phase in ("on ground", "landed") else None
        self.t_disarm = t
        self._end_verify(t)
        self._mark(t, "phase", "landed")
        return self._to("landed")

    def on_mode(self, t: float, mode: str) -> str | None:
        m = mode.upper()
        if m == self.mode:
            return None
        self.mode = m
        if "TAKEOFF" in m:
            self.t_takeoff = t if math.isnan(self.t_takeoff) else self.t_takeoff
            self._mark(t, "phase", "take-off")
            return self._to("take-off")
        if "OFFBOARD" in m:
            self._start_search(t)
            return self._to(self._flying_phase())
        if "LAND" in m or "RTL" in m:
            self.t_landing = t if math.isnan(self.t_landing) else self.t_landing
            self._end_verify(t)
            self._mark(t, "phase", "return" if "RTL" in m else "landing")
            return self._to("landing")
        if self.armed and self.phase not in ("landing", "landed"):  # PX4 holds after touchdown, until the disarm
            return self._to(self._flying_phase())
        return None

    def on_state(self, t: float, state: str) -> str | None:
        if state == self.state:
            return None
        was = self.state
        self.state = state
        if not self.searching and state not in ("", "wait-wind"):
            self._start_search(t)
        if state == "verify":
            self.verifications.append([float(t), math.nan])
            self._mark(t, "verify", f"verification {len(self.verifications)}")
        elif was == "verify":
            self._end_verify(t)
        if self.phase in ("take-off", "landing", "landed", "on ground"):
            return None
        if state in ("descend", "done"):  # the declaration follows in the same tick
            return self._to("descend")
        return self._to(self._flying_phase())

    def on_declared(self, t: float) -> str | None:
        if self.declared:
            return None
        self.declared = True
        self.t_declared = t
        self._end_verify(t)
        self._mark(t, "declared", "declared")
        if self.phase in ("landing", "landed"):
            return None
        return self._to("descend")

    # ------------------------------------------------------------------ helpers
    def _start_search(self, t: float) -> None:
        if not self.searching:
            self.searching = True
            self.t_search = t
            self._mark(t, "phase", "search")

    def _end_verify(self, t: float) -> None:
        if self.verifications and math.isnan(self.verifications[-1][1]):
            self.verifications[-1][1] = float(t)

    def flight_span(self) -> tuple[float, float] | None:
        """(arming, disarming) [s] when both are known, (arming, NaN) while flying, or None."""
        if math.isnan(self.t_arm):
            return None
        return self.t_arm, self.t_disarm


__all__ = ["MARKER_KINDS", "Marker", "PhaseTracker"]
