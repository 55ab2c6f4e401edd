"""Figures only the simulator can compute in ``--px4`` mode: the wind estimates and the declaration against the truth.

windseek's peripheral component sits on a PX4 MAVLink instance with forwarding on, so PX4 passes
it what the companion programs publish: the estimator's WIND_COV and the mission's declaration
(NAMED_VALUE_FLOAT ``SRC_N/E/D/CONF``, :mod:`wire.names`). :class:`TruthScore` scores each WIND_COV
against the true wind at the vehicle at the estimate's time stamp. In lockstep PX4's clock is the
simulation time (:func:`sitl.hil.messages.hil_time_us`), so the estimator's vehicle time and the
truth share one clock. Only airborne samples (true height over 1 m) are scored; a second RMSE
leaves out the first 10 s after each lift-off (the filter's start from a cold state).

Conventions: SI, NED, wind = air-mass velocity NED; simulation time in s.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from typing import Any

import numpy as np

from wire.names import SRC_CONF, SRC_NAMES

#: Airborne = true height above the start point over this [m].
AIRBORNE_M = 1.0
#: A truth sample is used for an estimate within this time of it [s].
MATCH_S = 0.1
#: The second RMSE leaves out the estimates of the first seconds of each flight (the lift-off transient) [s].
SETTLE_S = 10.0


class TruthScore:
    """Recent truth (``keep_s`` at ``rate_hz``), the WIND_COV score and the declared source."""

    def __init__(self, keep_s: float = 120.0, rate_hz: float = 50.0) -> None:
        n = int(keep_s * rate_hz)
        self.t: deque[float] = deque(maxlen=n)
        self.w: deque[np.ndarray] = deque(maxlen=n)
        self.h: deque[float] = deque(maxlen=n)
        self.err2 = np.zeros(3)
        self.n = 0
        self.err2_settled = np.zeros(3)
        self.n_settled = 0
        self._lift_off = -math.inf  # time the current flight passed AIRBORNE_M
        self._was_airborne = False
        self.received = 0
        self.last_estimate: list[float] | None = None
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
        """A message forwarded by PX4 (WIND_COV, NAMED_VALUE_FLOAT; others are ignored)."""
        mtype = msg.get_type()
        if mtype == "WIND_COV":
            self.received += 1
            w = np.array([msg.wind_x, msg.wind_y, msg.wind_z], dtype=float)
            self.last_estimate = [round(float(v), 3) for v in w]
            tr = self.at(msg.time_usec * 1e-6)
            t = msg.time_usec * 1e-6
            if tr is not None and tr[1] > AIRBORNE_M and np.all(np.isfinite(w)):
                self.err2 += (w - tr[0]) ** 2
                self.n += 1
                if t - self._lift_off >= SETTLE_S:
                    self.err2_settled += (w - tr[0]) ** 2
                    self.n_settled += 1
        elif mtype == "NAMED_VALUE_FLOAT":
            name = str(msg.name).rstrip("\x00")
            if name in SRC_NAMES:
                self._declared[name] = float(msg.value)
            elif name == SRC_CONF and all(n in self._declared for n in SRC_NAMES):
                self.declaration = {"declared_ned": [self._declared[n] for n in SRC_NAMES],
                                    "confidence": float(msg.value), "t_s": msg.time_boot_ms * 1e-3}  # fmt: skip

    def to_dict(self, sources_ned: list[list[float]]) -> dict[str, Any]:
        """The wind RMSE (NED and horizontal, m/s), the declaration and its horizontal error [m]."""
        rmse = np.sqrt(self.err2 / self.n) if self.n else np.full(3, math.nan)
        settled = np.sqrt(self.err2_settled / self.n_settled) if self.n_settled else np.full(3, math.nan)
        err = None
        if self.declaration is not None and sources_ned:
            dn = np.array(self.declaration["declared_ned"][:2])
            err = round(min(float(np.hypot(*(dn - np.array(s[:2])))) for s in sources_ned), 3)
        return {"wind_estimates_received": self.received, "wind_estimates_scored": self.n,
                "wind_rmse_ned_m_s": [round(float(v), 3) for v in rmse],
                "wind_rmse_horizontal_m_s": round(float(math.hypot(rmse[0], rmse[1])), 3),
                "wind_rmse_ned_after_10s_m_s": [round(float(v), 3) for v in settled],
                "wind_estimates_scored_after_10s": self.n_settled,
                "wind_last_estimate_ned_m_s": self.last_estimate, "true_sources_ned_m": sources_ned,
                "declared": self.declaration, "declared_error_horizontal_m": err,
                "path_length_m": round(self.path_m, 2)}  # fmt: skip
