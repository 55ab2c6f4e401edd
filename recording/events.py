"""The events of a run: the events log, the flight phases and the declaration.

:class:`EventsMixin` turns what happens (the autopilot's mode and arming, the strategy's states,
the mission's status texts and declaration, the lines of a log) into the events log
(``log/<channel>``, in plain words), the state lanes (``phases/mission``, ``phases/strategy``,
``phases/mode``), the path's colour (:attr:`SceneMixin.path_state`) and the markers the recorder
draws on the time series at close (:class:`~recording.phases.PhaseTracker`). Times are vehicle
seconds. The mission's wire names (``state: NAME``, ``SRC_N/E/D/CONF``) are those of :mod:`wire.names`.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np
import rerun as rr

from recording.phases import PhaseTracker
from recording.scene import SceneMixin
from recording.style import STATE_TEXT, TEXT_LEVELS, VecLike

SRC_KEYS = ("SRC_N", "SRC_E", "SRC_D")
#: Terminal colour codes (PX4's "\x1b[32mReady for takeoff!\x1b[0m") and other control characters.
_CONTROL = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|[\x00-\x08\x0b-\x1f\x7f]")
_SYS_COMP = re.compile(r"^\[?(\d+):(\d+)\]?$")


def readable(text: str) -> str:
    """A line for the events log: terminal colour codes and control characters removed, tabs and
    line breaks as spaces, surrounding blanks trimmed (autopilot messages carry all of these)."""
    return " ".join(_CONTROL.sub("", text.replace("\t", " ").replace("\n", " ")).split())


class EventsMixin(SceneMixin):
    """Events, phases and the declaration (see the module docstring)."""

    def _init_events(self) -> None:
        self.phases = PhaseTracker()
        self._src: dict[str, float] = {}
        self.declaration: tuple[float, list[float], float | None] | None = None
        self.true_sources_ned: list[list[float]] = []

    def text(self, t: float, text: str, level: str = "INFO", channel: str = "events") -> None:
        """A line of the events log at ``log/<channel>``; level one of TEXT_LEVELS.

        On the ``events`` channel the autopilot's own event lines of a log (``mode X``, ``armed``,
        ``disarmed``) also drive the flight phases (:meth:`autopilot_event`)."""
        level = level.upper()
        if level not in TEXT_LEVELS:
            raise ValueError(f"level = {level!r}: allowed values are {', '.join(TEXT_LEVELS)}")
        if channel == "events" and (text.startswith("mode ") or text in ("armed", "disarmed")):
            self.autopilot_event(t, text, level)
            return
        self._line(t, text, level, channel)

    def _line(self, t: float, text: str, level: str = "INFO", channel: str = "events") -> None:
        self.log_at(t, f"log/{channel}", rr.TextLog(readable(text), level=level))

    def _phase(self, t: float, phase: str | None) -> None:
        if phase is None:
            return
        self.log_at(t, "phases/mission", rr.StateChange(state=phase))
        p = self.phases
        if phase in ("search", "verify"):
            self.path_state = p.state or phase
        else:
            self.path_state = {"on ground": "ground", "armed": "ground", "descend": "descend"}.get(phase, phase)

    def flight_mode(self, t: float, mode: str) -> None:
        """The autopilot's flight mode changed (PX4 names, e.g. ``AUTO.TAKEOFF``, ``OFFBOARD``)."""
        if mode.upper() == self.phases.mode:
            return
        self.log_at(t, "phases/mode", rr.StateChange(state=mode))
        self._line(t, f"flight mode {mode}")
        self._phase(t, self.phases.on_mode(t, mode))

    def armed(self, t: float, armed: bool) -> None:
        """The vehicle was armed or disarmed."""
        if armed == self.phases.armed:
            return
        self._line(t, "armed" if armed else "disarmed")
        self._phase(t, self.phases.on_armed(t, armed))

    def strategy_state(self, t: float, state: str) -> None:
        """The strategy's state changed (e.g. ``surge``, ``cast``, ``verify``)."""
        if state == self.phases.state:
            return
        self.log_at(t, "phases/strategy", rr.StateChange(state=state))
        why = STATE_TEXT.get(state)
        self._line(t, f"strategy: {state}" + (f" – {why}" if why else ""), channel="mission")
        self._phase(t, self.phases.on_state(t, state))
        if self.phases.phase in ("search", "verify"):
            self.path_state = state

    def declare(self, t: float, ned: VecLike, confidence: float | None = None,
                credible_radius_m: float | None = None) -> None:  # fmt: skip
        """The strategy declared the source at ``ned`` [m] (see :meth:`SceneMixin.declared`)."""
        d = [float(v) for v in ned]
        self.declaration = (float(t), d, confidence)
        self.declared(t, d, confidence, credible_radius_m)
        conf = "" if confidence is None else f", confidence {100.0 * confidence:.0f} %"
        self._line(t, f"source declared at N {d[0]:.1f} E {d[1]:.1f} m, D {d[2]:.1f} m{conf}", channel="mission")
        self._phase(t, self.phases.on_declared(t))

    def sources(self, true_ned_list: Sequence[VecLike] | np.ndarray, declared_ned: VecLike | None = None,
                confidence: float | None = None, t: float | None = None) -> None:  # fmt: skip
        """True sources [m, NED] (static) and, optionally, a declaration at ``t`` (default: the latest time)."""
        true = [list(map(float, s)) for s in true_ned_list]
        if true and true != self.true_sources_ned:
            self.true_sources_ned = true
            self.true_sources(true)
        if declared_ned is not None:
            self.declare(self.t_latest if t is None else t, declared_ned, confidence)

    def mission_statustext(self, t: float, text: str, who: str = "mission", level: str = "INFO") -> None:
        """A STATUSTEXT from a mission or companion (``who``); ``state: NAME`` is a strategy state."""
        from wire.names import STATE_PREFIX

        if text.startswith(STATE_PREFIX):
            self.strategy_state(t, text[len(STATE_PREFIX) :].strip())
        else:
            if (m := _SYS_COMP.match(who)) is not None:  # an unknown sender, named by its MAVLink ids
                who = f"system {m[1]} component {m[2]}"
            self.text(t, f"{who}: {text}", level, channel="mission" if who == "mission" else "wire")

    def mission_named_value(self, t: float, name: str, value: float) -> None:
        """A NAMED_VALUE_FLOAT of the mission: ``SRC_N/E/D`` then ``SRC_CONF`` declare the source."""
        from wire.names import SRC_CONF

        if name in SRC_KEYS:
            self._src[name] = float(value)
        elif name == SRC_CONF and all(k in self._src for k in SRC_KEYS) and self.declaration is None:
            self.declare(t, [self._src[k] for k in SRC_KEYS], float(value))

    def autopilot_event(self, t: float, text: str, level: str = "INFO") -> None:
        """An event line of a log (``mode X``, ``armed``, ``disarmed``, or any autopilot message)."""
        if text.startswith("mode "):
            self.flight_mode(t, text[5:].strip())
        elif text in ("armed", "disarmed"):
            self.armed(t, text == "armed")
        else:
            self._line(t, text, level.upper() if level.upper() in TEXT_LEVELS else "INFO")



__all__ = ["SRC_KEYS", "EventsMixin", "readable"]
