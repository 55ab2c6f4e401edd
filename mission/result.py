"""What one mission reports (:class:`MissionResult`), whichever adapter flew it.

Units SI, NED (the autopilot's local frame); times are vehicle seconds from arming unless named.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from wire.jsonsafe import json_safe


class MissionError(RuntimeError):
    """The mission could not start (no autopilot, not healthy, arming refused, ...)."""


@dataclass
class MissionResult:
    """Summary of one mission (JSON-ready via :meth:`to_dict`).

    strategy, wind: the strategy's name and the wind source's mode; wind_source: one line saying
        where the wind came from (or why there was none).
    declared_ned: declared source (m, NED) or None; confidence 0..1; credible_radius_m: radius of the
        strategy's 90 % credible region around it (NaN when the strategy gives none).
    time_s: vehicle seconds from arming to the declaration (NaN without one).
    path_m: horizontal path from the start of the search to the declaration (or the end), m.
    cause: ``declared`` or an abort cause of :data:`mission.safety.CAUSES`; reasons: the lines said.
    landed / disarmed: final state, read from the vehicle; link_lost: the link was lost at some point.
    final_ned / home_ned: last and home positions (m, NED).
    verifications: the strategy's verification sweeps (``t_start_s``, ``duration_s``, ``outcome``,
        ``candidate_ne``), see ``mission/README.md``.
    wind_ned: the last wind estimate (m/s NED) the strategy used, or None when it had none.
    estimator: the estimator's counters (accepted, rejected, dropped, restarts, inputs).
    loop_lag_max_ms / loop_lag_p99_ms: how late the runner's event loop woke from a 20 ms sleep (wall ms):
        what a busy loop would do to setpoints and safety checks (MAVSDK runner only).
    ticks / ticks_skipped: strategy ticks run / skipped because the vehicle clock had moved past them
        (telemetry arriving late or in bursts: a tick is never queued behind another).
    """

    strategy: str
    wind: str
    wind_source: str = ""
    declared_ned: list[float] | None = None
    confidence: float = 0.0
    credible_radius_m: float = math.nan
    time_s: float = math.nan
    path_m: float = 0.0
    cause: str = ""
    reasons: list[str] = field(default_factory=list)
    landed: bool = False
    disarmed: bool = False
    link_lost: bool = False
    final_ned: list[float] | None = None
    home_ned: list[float] | None = None
    mission_time_s: float = math.nan
    wall_s: float = 0.0
    setpoints: int = 0
    setpoint_rate_hz: float = math.nan
    ticks: int = 0
    ticks_skipped: int = 0
    tick_rate_hz: float = math.nan
    clamped_setpoints: int = 0
    loop_lag_max_ms: float = math.nan
    loop_lag_p99_ms: float = math.nan
    state: str = ""
    wind_ned: list[float] | None = None
    estimator: dict[str, Any] = field(default_factory=dict)
    verifications: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out: dict[str, Any] = json_safe(d)
        return out
