"""Surge-cast (silkworm moth): surge upwind while the chemical is detected; when it is lost,
cast crosswind with growing amplitude until it is found again.

States:
- ``acquire``: nothing detected yet: crosswind sweeps about the start, growing, with a slow
  downwind drift (``cast_drift_m_s``) -- the plume is downwind of its source, so backing off
  widens the cross-section swept.
- ``surge``: detected within ``surge_persist_s``: fly upwind at ``speed_m_s``, steering
  toward the plume centreline (log-concentration weighted crosswind mean of the detections of
  the last ``memory_s``) with ``centerline_gain``; the near field of a source is only a few
  metres wide, so flying straight upwind from an off-axis hit would miss it.
- ``cast``: lost: sweeps of half-width ``cast_half_width_m`` about the centreline, each full
  sweep ``cast_growth`` times wider (up to ``cast_max_half_width_m``), drifting downwind;
  any detection returns to ``surge``.
- ``descend`` / ``done``: the plume ended (rule in ``mission.strategies.common``): fly over
  the most-upwind detection, descend, declare.

Without wind (``none``): "upwind" is the heading of the concentration gradient estimated
from the recent samples (least squares on log concentration), starting from
``initial_heading_deg`` (seeded draw by default); surges go along it and casts across it.
"""

from __future__ import annotations

import math

import numpy as np

from mission.strategies.base import Observation
from mission.strategies.common import BaseStrategy
from mission.strategies.params import SurgeCastParams


class SurgeCast(BaseStrategy):
    """Moth surge-cast on the upwind axis."""

    name = "surge-cast"
    p: SurgeCastParams

    def _reset(self) -> None:
        self.mode = "acquire"

    def _search(self, obs: Observation, u: np.ndarray, n: np.ndarray, new_det: bool, dt: float
                ) -> tuple[np.ndarray, str]:
        p = self.p
        m = self.memory
        pos = obs.position_ned[0:2]
        c_now = float(pos @ n)
        if m.n_detect > 0 and m.since_detect(obs.t) <= p.surge_persist_s:
            self.mode = "surge"
            self.sweep = None
            center = m.centerline(obs.t, n)
            lat = 0.0 if center is None else p.centerline_gain * (center - c_now)
            lat = float(np.clip(lat, -0.7 * p.speed_m_s, 0.7 * p.speed_m_s))
            fwd = math.sqrt(p.speed_m_s**2 - lat * lat)
            return fwd * u + lat * n, "surge"
        return self._lost_search(obs, u, n, "cast", p.cast_half_width_m, p.cast_growth, p.cast_max_half_width_m,
                                 p.cast_drift_m_s, p.cast_back_m)
