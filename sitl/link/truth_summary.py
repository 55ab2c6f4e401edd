"""``windseek sitl --exit-summary PATH``: the figures only the simulator can compute, written at shutdown.

A JSON file: RMSE of the received WIND_COV estimates against the true wind at the vehicle at the
estimate's time stamp (airborne samples only), the true source(s), the declared source and its
horizontal error, path length, final vehicle state. Runs in the link's thread (the endpoint's
``rx_hooks`` and the simulation's ``step_hooks``). SI, NED, wind = air-mass velocity NED;
simulation seconds.
"""

from __future__ import annotations

import bisect
import json
import math
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from wire.jsonsafe import json_safe
from wire.names import SRC_CONF, SRC_NAMES

if TYPE_CHECKING:
    from sitl.link.endpoint import Link
    from sitl.link.runner import SitlLink
    from sitl.simulation import Simulation

#: Airborne = true height above the start point over this [m] (wind RMSE is scored only then).
AIRBORNE_M = 1.0


def _name(msg: Any) -> str:
    return str(getattr(msg, "name", "")).rstrip("\x00")


class _Truth:
    """Recent true wind at the vehicle (simulation time, NED m/s), for scoring late estimates."""

    def __init__(self, keep_s: float = 60.0, rate_hz: float = 50.0) -> None:
        n = int(keep_s * rate_hz)
        self.t: deque[float] = deque(maxlen=n)
        self.w: deque[np.ndarray] = deque(maxlen=n)
        self.h: deque[float] = deque(maxlen=n)

    def add(self, t: float, wind: np.ndarray, height_m: float) -> None:
        self.t.append(t)
        self.w.append(np.array(wind, dtype=float))
        self.h.append(height_m)

    def at(self, t: float) -> tuple[np.ndarray, float] | None:
        """True wind and height at ``t`` (nearest recorded sample within 0.1 s), or None."""
        if not self.t:
            return None
        ts = self.t
        i = bisect.bisect_left(ts, t)
        best = None
        for j in (i - 1, i):
            if 0 <= j < len(ts) and (best is None or abs(ts[j] - t) < abs(ts[best] - t)):
                best = j
        if best is None or abs(ts[best] - t) > 0.1:
            return None
        return self.w[best], self.h[best]


class TruthSummary:
    """Scores WIND_COV estimates and the declared source against the simulation's truth."""

    def __init__(self, link: SitlLink, path: Path | str) -> None:
        self.link = link
        self.path = Path(path)
        self.truth = _Truth(rate_hz=link.sim.scenario.mode_rate_hz)
        self.err2 = np.zeros(3)
        self.n = 0
        self.n_received = 0
        self.last_estimate: list[float] | None = None
        self.path_m = 0.0
        self._prev: np.ndarray | None = None
        self.declared: dict[str, float] = {}
        self.declaration: dict[str, Any] | None = None
        self.statustexts = 0
        link.sim.step_hooks.append(self.on_tick)
        link.endpoint.rx_hooks.append(self.on_message)

    def on_tick(self, s: Simulation) -> None:
        pos = np.array(s.x[0:3], dtype=float)
        self.truth.add(s.t, s.wind_at_vehicle, -float(pos[2]))
        if self._prev is not None:
            self.path_m += float(np.linalg.norm(pos - self._prev))
        self._prev = pos

    def on_message(self, msg: Any, lk: Link) -> None:
        mtype = msg.get_type()
        if mtype == "WIND_COV":
            self.n_received += 1
            w = np.array([msg.wind_x, msg.wind_y, msg.wind_z], dtype=float)
            self.last_estimate = [round(float(v), 3) for v in w]
            tr = self.truth.at(msg.time_usec * 1e-6)
            if tr is not None and tr[1] > AIRBORNE_M and np.all(np.isfinite(w)):
                self.err2 += (w - tr[0]) ** 2
                self.n += 1
        elif mtype == "NAMED_VALUE_FLOAT":
            name = _name(msg)
            if name in SRC_NAMES:
                self.declared[name] = float(msg.value)
            elif name == SRC_CONF and all(n in self.declared for n in SRC_NAMES):
                self.declaration = {"declared_ned": [self.declared[n] for n in SRC_NAMES],
                                    "confidence": float(msg.value), "t_s": msg.time_boot_ms * 1e-3}  # fmt: skip
        elif mtype == "STATUSTEXT":
            self.statustexts += 1

    def true_sources(self) -> list[list[float]]:
        chem = self.link.sim.chem
        if chem is None:
            return []
        return [[float(v) for v in p] for p in chem.sources_ned]

    def to_dict(self) -> dict[str, Any]:
        sim = self.link.sim
        rmse = np.sqrt(self.err2 / self.n) if self.n else np.full(3, math.nan)
        d: dict[str, Any] = {
            "scenario": sim.scenario.name,
            "sim_time_s": round(sim.t, 3),
            "wind_estimates_received": self.n_received,
            "wind_estimates_scored": self.n,
            "wind_rmse_ned_m_s": [round(float(v), 3) for v in rmse],
            "wind_rmse_horizontal_m_s": round(float(math.hypot(rmse[0], rmse[1])), 3),
            "wind_last_estimate_ned_m_s": self.last_estimate,
            "wind_true_at_vehicle_ned_m_s": [round(float(v), 3) for v in sim.wind_at_vehicle],
            "true_sources_ned_m": self.true_sources(),
            "declared": self.declaration,
            "declared_error_horizontal_m": None,
            "path_length_m": round(self.path_m, 2),
            "final_position_ned_m": [round(float(v), 3) for v in sim.x[0:3]],
            "final_velocity_ned_m_s": [round(float(v), 3) for v in sim.x[3:6]],
            "final_mode": getattr(sim.fc.mode, "name", str(sim.fc.mode)),
            "armed": bool(sim.fc.armed),
            "crashed": bool(sim.crashed),
            "forwarded_messages": int(self.link.counters.get("forwarded", 0)),
            # Counts only: the key itself is never written anywhere.
            "signing": ({"rx_unauthenticated": int(self.link.counters.get("rx_unauthenticated", 0)),
                         "rx_mavlink1_signing": int(self.link.counters.get("rx_mavlink1_signing", 0)),
                         **self.link.endpoint.signing_counts()} if self.link.endpoint.signing_on else None),
            "statustexts_received": self.statustexts,
        }
        srcs = d["true_sources_ned_m"]
        if self.declaration is not None and srcs:
            dn = np.array(self.declaration["declared_ned"][:2])
            d["declared_error_horizontal_m"] = round(min(float(np.hypot(*(dn - np.array(s[:2])))) for s in srcs), 3)
        return json_safe(d)

    def write(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n")

    def close(self) -> None:
        """Write the summary (at shutdown)."""
        self.write()


__all__ = ["AIRBORNE_M", "TruthSummary"]
