"""Which MAVLink message feeds each estimator input, and the lines that say so.

The live core (``estimator.live``) listens for ``window_s`` seconds of the autopilot's clock,
then picks the best message streaming in every input group (``mavlink_decode.PREFERENCE``:
IMU HIL_SENSOR > HIGHRES_IMU > SCALED_IMU > RAW_IMU; attitude ATTITUDE_QUATERNION > ATTITUDE;
velocity LOCAL_POSITION_NED > GLOBAL_POSITION_INT > GPS_RAW_INT; rotor speeds ESC_STATUS >
RAW_RPM > ACTUATOR_OUTPUT_STATUS > SERVO_OUTPUT_RAW, telemetry before commands). A group with
nothing streaming by then is claimed by the first of its messages that comes later. Rates are
measured on the autopilot's clock (Hz). No I/O: the owner prints the lines.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from estimator.mavlink_decode import COMMAND_TYPES, MEASURED_TYPES, PREFERENCE

GROUP_LABEL = {"imu": "IMU", "attitude": "attitude", "velocity": "velocity", "rotors": "rotor speeds"}


def _or_list(names: tuple[str, ...]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " or " + names[-1]


class InputSelection:
    """The chosen message type per input group, what was seen, and the measured rates."""

    def __init__(self, window_s: float = 1.0) -> None:
        self.window_s = window_s
        self.chosen: dict[str, str] = {}
        self.seen: Counter[str] = Counter()
        self.selected = False
        self.t_start: float | None = None  # first stamped input, autopilot clock, s
        self._first: dict[str, float] = {}
        self._last: dict[str, float] = {}
        self._n: Counter[str] = Counter()
        self._forced: dict[str, str] = {}  # group -> message type the owner switched it to (switch())

    def observe(self, mtype: str, t: float | None) -> None:
        """Count an input message (``t``: its boot-clock time stamp, s, or None)."""
        self.seen[mtype] += 1
        if t is None:
            return
        if self.t_start is None:
            self.t_start = t
        if mtype not in self._first or t < self._first[mtype]:
            self._first[mtype] = t
        self._last[mtype] = max(t, self._last.get(mtype, t))
        self._n[mtype] += 1

    def due(self, t: float | None) -> bool:
        """True when the listening window has passed at autopilot time ``t`` and nothing is chosen yet."""
        return not self.selected and t is not None and self.t_start is not None and t - self.t_start >= self.window_s

    def select(self) -> None:
        """Choose the preferred message seen in every group."""
        for group, names in PREFERENCE.items():
            name = next((n for n in names if self.seen[n]), None)
            if name is not None:
                self.chosen[group] = name
        self.chosen.update(self._forced)
        self.selected = True

    def claim(self, group: str, mtype: str) -> bool:
        """After the selection, the first message of a group that had nothing takes it; True if it did."""
        if not self.selected or group in self.chosen:
            return False
        self.chosen[group] = mtype
        return True

    def switch(self, group: str, mtype: str) -> bool:
        """Feed ``group`` from ``mtype`` from now on, whatever the preference (the owner knows better; before the
        selection it is kept for it); True if an input in use changed."""
        self._forced[group] = mtype
        if not self.selected:
            return False
        changed = self.chosen.get(group) != mtype
        self.chosen[group] = mtype
        return changed

    def rate_hz(self, mtype: str) -> float | None:
        """Measured rate of a stamped message type on the autopilot's clock, Hz (None: unknown)."""
        n = self._n[mtype]
        span = self._last.get(mtype, 0.0) - self._first.get(mtype, 0.0)
        return (n - 1) / span if n > 1 and span > 0.0 else None

    def restart_clock(self) -> None:
        """Forget the time stamps (after the autopilot's clock was reset); keep the choices."""
        self._first.clear()
        self._last.clear()
        self._n.clear()
        self.t_start = None

    # ------------------------------------------------------------------ lines
    def inputs_line(self) -> str:
        """One line: what feeds each input, e.g. ``inputs: IMU HIGHRES_IMU 50 Hz, attitude ...``."""
        parts = []
        for group in PREFERENCE:
            mtype = self.chosen.get(group)
            label = GROUP_LABEL[group]
            if mtype is None:
                parts.append(f"{label} none ({self._missing_reason(group)})")
                continue
            rate = self.rate_hz(mtype)
            hz = f" {rate:.0f} Hz" if rate is not None and group == "imu" else ""
            if group == "rotors" and mtype in COMMAND_TYPES:
                parts.append(f"rotor speeds from {mtype} through the motor model (no ESC telemetry)")
            else:
                parts.append(f"{label} {mtype}{hz}")
        return "inputs: " + ", ".join(parts)

    def missing(self) -> list[str]:
        """The groups the filter cannot run without that have no message yet (velocity is optional)."""
        return [g for g in ("imu", "attitude", "rotors") if g not in self.chosen]

    def waiting_line(self) -> str:
        """What the filter lacks, e.g. ``waiting for inputs: no rotor speeds (no ESC_STATUS, ... seen)``."""
        miss = self.missing()
        if not miss:
            return "waiting for the first IMU sample with attitude and rotor speeds"
        return "waiting for inputs: " + "; ".join(f"no {GROUP_LABEL[g]} ({self._missing_reason(g)})" for g in miss)

    def _missing_reason(self, group: str) -> str:
        return f"no {_or_list(PREFERENCE[group])} seen"


def filter_waiting_line(missing: list[str], rotors_from: str | None, esc_seen: np.ndarray,
                        esc_failed: np.ndarray) -> str:  # fmt: skip
    """Every input has a message, yet the filter has not run: which sample it still lacks (``missing``: the
    filter's own list; ``rotors_from``: the rotor speeds' message type; ESCs reported / reported failed,
    by rotor)."""
    why = []
    for name in missing:
        if name == "rotor speeds" and esc_failed.any():
            rotors = ", ".join(str(i + 1) for i in np.flatnonzero(esc_failed))
            why.append(f"no rotor speeds (ESC_INFO reports the ESC of rotor {rotors} failed)")
        elif name == "rotor speeds" and rotors_from in MEASURED_TYPES:
            seen = ", ".join(str(i + 1) for i in np.flatnonzero(esc_seen)) or "none"
            why.append(f"no complete set of rotor speeds (rotors reported: {seen})")
        else:
            why.append(f"no {name} accepted yet")
    return "waiting for inputs: " + ("; ".join(why) if why else "no IMU sample accepted yet")
