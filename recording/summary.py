"""The run summary carried by the recording itself: result, times, path, wind error, what is missing.

:class:`RunSummary` is filled by whoever knows the run (``windseek sitl --rrd`` from the truth and
the wire, ``windseek demo`` from the mission's result, the in-process trial recorder, ``windseek
review``) and written by :meth:`recording.recorder.RunRecorder.summary` as

- a Markdown document at ``summary`` (the summary panel of the layout),
- a recording property ``result`` with the key figures as numbers, and the whole summary as JSON
  (``result.json``), which :mod:`recording.read` reads back.

Units SI, NED; times ``t_*`` are vehicle seconds (the recording's timeline), durations are counted
from arming (what the mission reports as its times).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any

#: A declaration within this horizontal distance of the true source counts as found [m]
#: (the project's success radius: ``windseek demo``, ``mission.runners.inprocess``).
FOUND_RADIUS_M = 5.0


def _f(v: float | None, fmt: str = ".1f", unit: str = "") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{format(v, fmt)}{unit}"


@dataclass
class RunSummary:
    """What a run did (see the module docstring); every field is optional."""

    kind: str = "run"
    scenario: str | None = None
    strategy: str | None = None
    seed: int | None = None
    wind_source: str | None = None
    found: bool | None = None
    outcome: str = ""
    cause: str | None = None
    declared_ned: list[float] | None = None
    confidence: float | None = None
    credible_radius_m: float | None = None
    true_sources_ned: list[list[float]] = field(default_factory=list)
    error_m: float | None = None
    t_arm_s: float | None = None
    t_search_s: float | None = None
    t_declared_s: float | None = None
    t_disarm_s: float | None = None
    time_to_declaration_s: float | None = None
    mission_time_s: float | None = None
    search_path_m: float | None = None
    total_path_m: float | None = None
    reach_path_m: float | None = None
    start_distance_m: float | None = None
    wind_rmse_ned_m_s: list[float] | None = None
    wind_rmse_horizontal_m_s: float | None = None
    wind_scored: int | None = None
    verifications: list[dict[str, Any]] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    extra: dict[str, str] = field(default_factory=dict)
    #: False for a run without a search (a flight log review): no search tables, no plume notes.
    search: bool = True

    # ------------------------------------------------------------------ derived
    @property
    def path_ratio(self) -> float | None:
        """Search path over the start distance (1 = straight to the source)."""
        if self.search_path_m is None or not self.start_distance_m:
            return None
        return self.search_path_m / self.start_distance_m

    @property
    def reach_ratio(self) -> float | None:
        """Path until first within ``FOUND_RADIUS_M`` of the source, over the start distance."""
        if self.reach_path_m is None or not self.start_distance_m or not math.isfinite(self.reach_path_m):
            return None
        return self.reach_path_m / self.start_distance_m

    def score(self) -> None:
        """Fill the declared error and ``found`` from the declaration and the true sources (if unset)."""
        if self.declared_ned is not None and self.true_sources_ned and self.error_m is None:
            d = self.declared_ned
            self.error_m = min(math.hypot(d[0] - s[0], d[1] - s[1]) for s in self.true_sources_ned)
        if self.found is None and self.true_sources_ned and self.strategy not in (None, "", "none"):
            self.found = self.error_m is not None and self.error_m <= FOUND_RADIUS_M
        if not self.outcome:
            if self.declared_ned is None:
                self.outcome = "no declaration" + (f" ({self.cause})" if self.cause else "")
            elif self.error_m is not None:
                self.outcome = f"declared {self.error_m:.1f} m from the true source"
            else:
                self.outcome = "declared (no true source to compare with)"

    # ------------------------------------------------------------------ storage
    def fill_from_phases(self, ph: Any, declared: bool, now_s: float) -> None:
        """The times and the cause a recording that listens to the wire knows: time to declaration and mission
        time from the phases ``ph`` (a :class:`recording.phases.PhaseTracker`; a flight still armed ends at
        ``now_s``), and "no declaration received" for a strategy's run without one (``declared`` False)."""
        if math.isfinite(ph.t_declared) and math.isfinite(ph.t_arm):
            self.time_to_declaration_s = round(ph.t_declared - ph.t_arm, 2)
        if math.isfinite(ph.t_arm):
            end = ph.t_disarm if math.isfinite(ph.t_disarm) else now_s
            self.mission_time_s = round(end - ph.t_arm, 2)
        if not declared and self.strategy:
            self.cause = "no declaration received"

    def to_json(self) -> str:
        return json.dumps(_finite(asdict(self)), allow_nan=False)

    @classmethod
    def from_json(cls, text: str) -> RunSummary:
        d = json.loads(text)
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in known})

    def properties(self) -> dict[str, Any]:
        """Key figures for the ``result`` recording property (numbers, no None)."""
        pairs: dict[str, Any] = {
            "found": self.found, "error_m": self.error_m, "confidence": self.confidence,
            "time_to_declaration_s": self.time_to_declaration_s, "t_declared_s": self.t_declared_s,
            "t_arm_s": self.t_arm_s, "search_path_m": self.search_path_m, "total_path_m": self.total_path_m,
            "path_ratio": self.path_ratio, "reach_ratio": self.reach_ratio,
            "wind_rmse_horizontal_m_s": self.wind_rmse_horizontal_m_s, "verifications": len(self.verifications),
        }  # fmt: skip
        out: dict[str, Any] = {k: v for k, v in pairs.items()
                               if v is not None and not (isinstance(v, float) and not math.isfinite(v))}  # fmt: skip
        out["json"] = self.to_json()
        return out

    # ------------------------------------------------------------------ text
    def title(self) -> str:
        parts = [p for p in (self.scenario, self.strategy) if p]
        if self.seed is not None:
            parts.append(f"seed {self.seed}")
        return " · ".join(parts) or self.kind

    def markdown(self) -> str:
        """The summary as Markdown (what the summary panel shows): the result and the key figures
        first, as short lines, then the details."""
        self.score()
        found = {True: "**FOUND**: ", False: "**NOT FOUND**: ", None: "not scored: "}[self.found]
        if self.found is None and self.declared_ned is None and not self.outcome.startswith("no declaration"):
            found = ""  # a result of its own (a flight log review's wind figure): nothing to score
        lines = [f"### {self.title()}", "", f"{found}{self.outcome}. _{self.kind}_", ""]
        lines += [f"- {x}" for x in self._key_lines()]
        lines += [f"- {k}: {v}" for k, v in self.extra.items()]
        lines += ["", "#### Times (vehicle clock, s)", ""]
        if not self.search:
            lines += _table(("armed", "disarmed"), [(_f(self.t_arm_s), _f(self.t_disarm_s))])
            return "\n".join(self._tail(lines, REVIEW_NOTES)) + "\n"
        lines += _table(("armed", "search start", "declared", "disarmed"),
                        [(_f(self.t_arm_s), _f(self.t_search_s), _f(self.t_declared_s), _f(self.t_disarm_s))])
        lines += ["", "#### Path (horizontal, m)", ""]
        lines += _table(("search path", "flown in total", "start distance", "path / start", "to within 5 m / start"),
                        [(_f(self.search_path_m), _f(self.total_path_m), _f(self.start_distance_m),
                          _f(self.path_ratio, ".2f"), _f(self.reach_ratio, ".2f"))])  # fmt: skip
        if self.verifications:
            lines += ["", "#### Verification sweeps", ""]
            lines += _table(("#", "start (s)", "duration (s)", "outcome"),
                            [(str(i + 1), _f(v.get("t_start_s")), _f(v.get("duration_s")),
                              v.get("outcome") or "running") for i, v in enumerate(self.verifications)])  # fmt: skip
        return "\n".join(self._tail(lines, READING_NOTES)) + "\n"

    def _tail(self, lines: list[str], reading: tuple[str, ...]) -> list[str]:
        """What is missing, then the notes and how to read the recording."""
        if self.missing:
            lines += ["", "#### Missing from this recording", ""] + [f"- {m}" for m in self.missing]
        return lines + ["", "#### Reading it", ""] + [f"- {n}" for n in (*self.notes, *reading)]

    def _key_lines(self) -> list[str]:
        """The headline figures, one short line each."""
        out = []
        if self.declared_ned is not None:
            d = self.declared_ned
            conf = "" if self.confidence is None else f", confidence {100 * self.confidence:.0f} %"
            cr = self.credible_radius_m
            cr_s = "" if cr is None or not math.isfinite(cr) else f", credible radius {cr:.1f} m"
            out.append(f"declared N {d[0]:.1f} E {d[1]:.1f} D {d[2]:.1f} m{conf}{cr_s}")
        for s in self.true_sources_ned:
            out.append(f"true source N {s[0]:.1f} E {s[1]:.1f} D {s[2]:.1f} m")
        if self.error_m is not None:
            out.append(f"declared error {self.error_m:.1f} m horizontally (found = within {FOUND_RADIUS_M:g} m)")
        if self.time_to_declaration_s is not None:
            at = "" if self.t_declared_s is None else f" (t = {self.t_declared_s:.1f} s)"
            out.append(f"time to declaration {self.time_to_declaration_s:.1f} s after arming{at}")
        if self.search_path_m is not None:
            parts = (None if self.path_ratio is None else f"{self.path_ratio:.2f} x start distance",
                     None if self.reach_ratio is None else f"{self.reach_ratio:.2f} x until within 5 m")
            ratios = ", ".join(x for x in parts if x)
            out.append(f"path {self.search_path_m:.1f} m searched" + (f" ({ratios})" if ratios else "")
                       + ("" if self.total_path_m is None else f", {self.total_path_m:.1f} m flown"))  # fmt: skip
        if self.wind_rmse_horizontal_m_s is not None:
            r: list[float | None] = [None, None, None]
            if self.wind_rmse_ned_m_s is not None:
                r = list(self.wind_rmse_ned_m_s)
            n = "" if self.wind_scored is None else f", {self.wind_scored} estimates while airborne"
            out.append(f"wind RMSE vs truth {self.wind_rmse_horizontal_m_s:.2f} m/s horizontal "
                       f"(N {_f(r[0], '.2f')}, E {_f(r[1], '.2f')}, D {_f(r[2], '.2f')}{n})")  # fmt: skip
        if self.wind_source:
            out.append(f"wind source: {self.wind_source}")
        return out


READING_NOTES = (
    "Clock: every panel uses vehicle time (simulation time; in a reviewed log, the time since the log's "
    "start); durations such as the time to declaration count from arming.",
    "Time series: truth blue, estimate orange inside its light orange ±2σ band, raw estimate grey; "
    "vertical lines mark take-off, search start, landing (grey), each verification sweep (purple) and the "
    "declaration (green).",
    "Chemical: log10 of the reading in mg/m³; a reading of 0 (below detection) is drawn at the bottom edge, "
    "the red line is the detection threshold.",
    "Map: north up; path coloured by strategy state, dots where the sensor detected the plume (coloured "
    "by concentration), plume at flight altitude (yellow = faint, dark red = strong), true source red, "
    "declared source green.",
)


#: How to read a flight log review's recording (no search, no plume).
REVIEW_NOTES = (
    READING_NOTES[0],
    "Flight: altitude (m up: the log's local position and, in brown, the GPS on the same origin), and in "
    "the flight tab ground velocity north / east / down and roll / pitch / yaw (deg); battery and GPS fix "
    "in their own tab; every plot names its series in its legend. Vertical lines mark take-off and landing.",
    "Wind: our estimate orange inside its light orange ±2σ band (trusted samples only), the autopilot's own "
    "estimate green.",
    "Map: north up; the flown path (local position), the GPS fixes as a brown track.",
)


def _table(head: tuple[str, ...], rows: list[tuple[str, ...]]) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    return out


def _finite(x: Any) -> Any:
    """NaN/inf -> None, recursively (strict JSON)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x


__all__ = ["FOUND_RADIUS_M", "READING_NOTES", "REVIEW_NOTES", "RunSummary"]
