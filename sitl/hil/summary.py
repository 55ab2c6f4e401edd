"""Figures only the simulator can compute with PX4 or ArduPilot flying: the wind estimates and the declaration
against the truth.

windseek's peripheral component sits on a MAVLink port of the autopilot, which passes it what the
companion programs publish: the estimator's WIND_COV and the mission's declaration (NAMED_VALUE_FLOAT
``SRC_N/E/D/CONF``, :mod:`wire.names`). :class:`TruthScore` scores each wind estimate against the true
wind at the vehicle at the estimate's time stamp, **by source**: WIND_COV from a companion component
(windseek's estimator is 191) is ``estimator``; the autopilot's own estimate (component 1: PX4 EKF2's
WIND_COV, ArduPilot EKF3's WIND, which has no time stamp and no covariance: scored at the newest truth
sample) is ``autopilot``, so neither is mixed into the other's figures. In lockstep the autopilot's
clock is the simulation time, so the estimator's vehicle time and the truth share one clock. Only
airborne samples (true height over 1 m) are scored; figures per source in :mod:`sitl.hil.wind_score`.

Conventions: SI, NED, wind = air-mass velocity NED; simulation time in s.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from typing import Any

import numpy as np

from sitl.hil.wind_score import WindScore
from wire.names import SRC_CONF, SRC_NAMES

#: Airborne = true height above the start point over this [m].
AIRBORNE_M = 1.0
#: A truth sample is used for an estimate within this time of it [s].
MATCH_S = 0.1
#: The second RMSE leaves out the estimates of the first seconds of each flight (the lift-off transient) [s].
SETTLE_S = 10.0


#: MAV_COMP_ID_AUTOPILOT1: a wind estimate from this component is the autopilot's own.
AUTOPILOT_COMPONENT = 1


class TruthScore:
    """Recent truth (``keep_s`` at ``rate_hz``), the wind scores by source and the declared source."""

    def __init__(self, keep_s: float = 120.0, rate_hz: float = 50.0) -> None:
        n = int(keep_s * rate_hz)
        self.t: deque[float] = deque(maxlen=n)
        self.w: deque[np.ndarray] = deque(maxlen=n)
        self.h: deque[float] = deque(maxlen=n)
        self.estimator = WindScore(SETTLE_S)
        self.autopilot = WindScore(SETTLE_S)
        self._lift_off = -math.inf  # time the current flight passed AIRBORNE_M
        self._was_airborne = False
        self.path_m = 0.0
        self._prev: np.ndarray | None = None
        self._declared: dict[str, float] = {}
        self.declaration: dict[str, Any] | None = None

    def add(self, t: float, pos_ned: np.ndarray, wind_ned: np.ndarray) -> None:
        """One truth sample: time [s], position (NED, m), wind at the vehicle (NED, m/s)."""
        pos = np.array(pos_ned, dtype=float)
        self.t.append(float(t))
        self.w.append(np.array(wind_ned, dtype=float))
        self.h.append(-float(pos[2]))
        airborne = -float(pos[2]) > AIRBORNE_M
        if airborne and not self._was_airborne:
            self._lift_off = float(t)
        self._was_airborne = airborne
        if self._prev is not None:
            self.path_m += float(np.linalg.norm(pos - self._prev))
        self._prev = pos

    def at(self, t: float) -> tuple[np.ndarray, float] | None:
        """True wind and height at ``t`` (the nearest sample within :data:`MATCH_S`), or None."""
        ts = self.t
        if not ts:
            return None
        i = bisect.bisect_left(ts, t)
        best = min((j for j in (i - 1, i) if 0 <= j < len(ts)), key=lambda j: abs(ts[j] - t))
        if abs(ts[best] - t) > MATCH_S:
            return None
        return self.w[best], self.h[best]

    def on_message(self, msg: Any) -> None:
        """A message the autopilot passed on (WIND_COV, WIND, NAMED_VALUE_FLOAT; others are ignored)."""
        mtype = msg.get_type()
        if mtype == "WIND_COV":
            own = msg.get_srcComponent() == AUTOPILOT_COMPONENT
            w = np.array([msg.wind_x, msg.wind_y, msg.wind_z], dtype=float)
            self._score(self.autopilot if own else self.estimator, msg.time_usec * 1e-6, w, float(msg.var_horiz))
        elif mtype == "WIND" and self.t:
            d = math.radians(float(msg.direction))  # where the wind comes from; speed in the ground plane
            sp = float(msg.speed)
            w = np.array([-sp * math.cos(d), -sp * math.sin(d), float(msg.speed_z)])
            self._score(self.autopilot, self.t[-1], w, None)
        elif mtype == "NAMED_VALUE_FLOAT":
            name = str(msg.name).rstrip("\x00")
            if name in SRC_NAMES:
                self._declared[name] = float(msg.value)
            elif name == SRC_CONF and all(n in self._declared for n in SRC_NAMES):
                self.declaration = {"declared_ned": [self._declared[n] for n in SRC_NAMES],
                                    "confidence": float(msg.value), "t_s": msg.time_boot_ms * 1e-3}  # fmt: skip

    def _score(self, score: WindScore, t: float, w: np.ndarray, var_h: float | None) -> None:
        score.received += 1
        score.last_estimate = [round(float(v), 3) for v in w]
        tr = self.at(t)
        if tr is not None and tr[1] > AIRBORNE_M and np.all(np.isfinite(w)):
            score.add(t, w, tr[0], t - self._lift_off, var_h)

    def to_dict(self, sources_ned: list[list[float]]) -> dict[str, Any]:
        """The estimator's wind figures (flat keys, as before), the autopilot's (``autopilot_wind``), the
        declaration and its horizontal error [m]."""
        e = self.estimator.to_dict()
        err = None
        if self.declaration is not None and sources_ned:
            dn = np.array(self.declaration["declared_ned"][:2])
            err = round(min(float(np.hypot(*(dn - np.array(s[:2])))) for s in sources_ned), 3)
        h = e["rmse_horizontal_m_s"]
        return {"wind_estimates_received": e["received"], "wind_estimates_scored": e["scored"],
                "wind_rmse_ned_m_s": e["rmse_ned_m_s"], "wind_rmse_horizontal_m_s": h,
                "wind_rmse_ned_after_10s_m_s": e["rmse_ned_after_settle_m_s"],
                "wind_estimates_scored_after_10s": e["scored_after_settle"],
                "wind_rmse_1s_ned_m_s": e["rmse_1s_ned_m_s"],
                "wind_rmse_1s_horizontal_m_s": e["rmse_1s_horizontal_m_s"],
                "wind_coverage_95_horizontal": e["coverage_95_horizontal"], "wind_series_1s": e["series_1s"],
                "wind_last_estimate_ned_m_s": e["last_estimate_ned_m_s"], "autopilot_wind": self.autopilot.to_dict(),
                "true_sources_ned_m": sources_ned, "declared": self.declaration, "declared_error_horizontal_m": err,
                "path_length_m": round(self.path_m, 2)}  # fmt: skip
