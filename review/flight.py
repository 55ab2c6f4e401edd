"""What a flight log holds, decoded to the project's conventions: the common ground of the readers.

:class:`FlightData` is produced by :func:`review.tlog.read_tlog` and :func:`review.ulog.read_ulog`
and consumed by :mod:`review.convert`. Everything is SI, NED/FRD; wind is the air-mass
velocity in NED (m/s); quaternions are ``[w, x, y, z]`` body FRD -> NED; rotor speeds are
rad/s in the rotor order of ``vehicle.rotor_model`` (1 front right, 2 rear right, 3 rear left,
4 front left). Times are seconds of the autopilot's boot clock (the project's SITL: simulation
time), the same clock as the log's own time stamps; the Rerun ``sim_time`` timeline uses it.

Estimator inputs are :class:`Input` rows ``(t, order, kind, value)`` with ``kind`` one of

    attitude    q [w, x, y, z]                      (held input)
    rotors      measured rotor speeds (4,) rad/s     (held input; ESC telemetry)
    rotor_cmd   commanded rotor speeds (4,) rad/s    (actuator outputs; through the motor lag)
    imu         (specific force (3,) m/s^2 FRD, gyro (3,) rad/s FRD or None)
    velocity    NED ground velocity (3,) or north/east (2,) m/s, at its time of validity

``order`` breaks ties at equal times (held inputs before the IMU sample that uses them).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

#: Tie-break order of the input kinds at equal time stamps.
INPUT_ORDER = {"attitude": 0, "rotors": 0, "rotor_cmd": 0, "imu": 1, "velocity": 2}
#: Time stamps beyond this [s] are not on a boot clock (UNIX or GPS epoch): the readers drop them.
MAX_BOOT_TIME_S = 1.0e7


class Input(NamedTuple):
    """One estimator input (see the module docstring)."""

    t: float
    order: int
    kind: str
    value: Any


def make_input(t: float, kind: str, value: Any) -> Input:
    return Input(float(t), INPUT_ORDER[kind], kind, value)


@dataclass
class Series:
    """A time series: t [s] (N,) and values (N,) or (N, k)."""

    t: np.ndarray
    v: np.ndarray
    name: str = ""

    @classmethod
    def from_rows(cls, rows: list[tuple[float, Any]], name: str = "", width: int | None = None) -> Series:
        """From (t, value) rows, sorted by time (stable)."""
        if not rows:
            shape = (0,) if width is None else (0, width)
            return cls(np.zeros(0), np.zeros(shape), name)
        rows = sorted(rows, key=lambda r: r[0])
        return cls(np.array([r[0] for r in rows], dtype=float), np.array([r[1] for r in rows], dtype=float), name)

    def __len__(self) -> int:
        return len(self.t)


def _empty(width: int | None = None, name: str = "") -> Series:
    return Series.from_rows([], name, width)


@dataclass
class FlightData:
    """A decoded flight log (see the module docstring for units and frames).

    Attributes:
        path: the log file.
        kind: ``"tlog"`` or ``"ulog"``.
        autopilot: who wrote it, as far as the log tells (``"PX4"``, ``"ArduPilot"``,
            ``"windseek SITL"``, ``"unknown"``).
        counts: messages per MAVLink type (tlog) or samples per ULog topic.
        inputs: estimator inputs, sorted by (t, order).
        sources: group (``imu``, ``attitude``, ``velocity``, ``rotors``, ``rotor_cmd``,
            ``position``, ``chem``, ``truth``, ``autopilot_wind``, ``in_air``) -> message
            type or topic it came from; a group that is absent was not in the log.
        position: vehicle position [m, NED] (N, 3), origin = the log's local origin (the
            first fix for logs with only global positions).
        attitude: attitude quaternions (N, 4) for display.
        chem: chemical reading [mg/m^3].
        truth_wind: simulation-only true wind at the vehicle (air-mass velocity NED, m/s).
        autopilot_wind: the autopilot's own wind estimate (air-mass velocity NED, m/s; down
            NaN when it has none).
        rotors: rotor speeds [rad/s] (N, 4) for display: measured, or implied by the
            actuator outputs when ``sources["rotors"]`` is absent.
        in_air: (t, in air?) state changes (landed state or, failing that, arming).
        texts: (t, text, level) events: mode and arming changes, autopilot status texts.
        notes: reader remarks (dropped time stamps, undecodable frames, ...).
    """

    path: Path
    kind: str
    autopilot: str = "unknown"
    counts: Counter[str] = field(default_factory=Counter)
    inputs: list[Input] = field(default_factory=list)
    sources: dict[str, str] = field(default_factory=dict)
    position: Series = field(default_factory=lambda: _empty(3, "position"))
    attitude: Series = field(default_factory=lambda: _empty(4, "attitude"))
    chem: Series = field(default_factory=lambda: _empty(None, "chem"))
    truth_wind: Series = field(default_factory=lambda: _empty(3, "truth"))
    autopilot_wind: Series = field(default_factory=lambda: _empty(3, "autopilot"))
    rotors: Series = field(default_factory=lambda: _empty(4, "rotors"))
    in_air: list[tuple[float, bool]] = field(default_factory=list)
    texts: list[tuple[float, str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def sort_inputs(self) -> None:
        self.inputs.sort(key=lambda r: (r.t, r.order))

    @property
    def time_range(self) -> tuple[float, float]:
        """First and last time stamp [s] of any decoded data (NaN, NaN for an empty log)."""
        ts = [self.inputs[0].t, self.inputs[-1].t] if self.inputs else []
        for s in (self.position, self.attitude, self.chem, self.truth_wind, self.autopilot_wind, self.rotors):
            if len(s):
                ts += [float(s.t[0]), float(s.t[-1])]
        if not ts:
            return math.nan, math.nan
        return min(ts), max(ts)

    @property
    def duration_s(self) -> float:
        t0, t1 = self.time_range
        return 0.0 if not math.isfinite(t0) else t1 - t0

    def airborne_segments(self) -> list[tuple[float, float]]:
        """Time intervals [s] in the air, from :attr:`in_air`; the whole log when that is unknown."""
        t0, t1 = self.time_range
        if not math.isfinite(t0):
            return []
        if not self.in_air:
            return [(t0, t1)]
        segs: list[tuple[float, float]] = []
        start: float | None = None
        for t, air in sorted(self.in_air):
            if air and start is None:
                start = t
            elif not air and start is not None:
                segs.append((start, t))
                start = None
        if start is not None:
            segs.append((start, t1))
        # clipped to the data: a state change timed outside it must not add time nobody logged
        segs = [(max(a, t0), min(b, t1)) for a, b in segs]
        return [s for s in segs if s[1] > s[0]]


def state_changes(rows: list[tuple[float, bool]]) -> list[tuple[float, bool]]:
    """Keep only the samples where a boolean state changes (the first one always)."""
    out: list[tuple[float, bool]] = []
    for t, v in sorted(rows):
        if not out or out[-1][1] != v:
            out.append((t, v))
    return out


def pwm_to_fraction(values: np.ndarray) -> np.ndarray:
    """Actuator outputs to a throttle fraction in [0, 1]: PWM in microseconds (1000-2000 us)
    when any value exceeds 100, otherwise already normalized (0..1)."""
    v = np.asarray(values, dtype=float)
    if np.nanmax(np.abs(v), initial=0.0) > 100.0:
        v = (v - 1000.0) / 1000.0
    return np.clip(v, 0.0, 1.0)


__all__ = [
    "INPUT_ORDER",
    "MAX_BOOT_TIME_S",
    "FlightData",
    "Input",
    "Series",
    "make_input",
    "pwm_to_fraction",
    "state_changes",
]
