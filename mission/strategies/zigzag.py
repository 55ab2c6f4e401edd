"""Zig-zag (dung beetle, paper Fig. 19): cross the plume diagonally upwind, turning back at
each edge; when the plume ends, the source is just upwind: descend and declare it.

States:
- ``acquire``: nothing detected yet: crosswind sweeps about the start, growing, drifting
  slowly downwind (as surge-cast's cast).
- ``zig``: legs at ``angle_deg`` off the upwind direction, alternately left and right. A leg
  turns back at the plume edge -- ``edge_s`` without a detection after having detected in
  this leg -- or, whatever the readings, ``leg_max_half_width_m`` off the centreline (the
  intermittent far field has gaps inside the plume; the cap keeps the legs from running away).
- ``lost``: no detection for ``lost_s`` + ``edge_s``: crosswind sweeps about the centreline,
  half-width ``lost_half_width_m`` growing by ``lost_growth`` per sweep, drifting downwind;
  a detection resumes ``zig``.
- ``descend`` / ``done``: the plume ended (rule in ``mission.strategies.common``): fly over
  the most-upwind detection, descend, declare.

Without wind (``none``): the zig-zag axis is the heading of the concentration gradient
estimated from the detections and non-detections of the recent legs (least squares on log
concentration), starting from ``initial_heading_deg`` (seeded draw by default): the legs
themselves sample the crosswind profile, so the axis turns toward the source as hits come in.
"""

from __future__ import annotations

import math

import numpy as np

from mission.strategies.base import Observation
from mission.strategies.common import BaseStrategy
from mission.strategies.params import ZigzagParams


class Zigzag(BaseStrategy):
    """Dung-beetle zig-zag across the plume, upwind."""

    name = "zigzag"
    p: ZigzagParams

    def _reset(self) -> None:
        self.side = 1.0  # +1: legs toward +n (right of upwind), -1: left
        self.leg_hit = False
        self.mode = "acquire"

    def _search(self, obs: Observation, u: np.ndarray, n: np.ndarray, new_det: bool, dt: float
                ) -> tuple[np.ndarray, str]:
        p = self.p
        m = self.memory
        pos = obs.position_ned[0:2]
        c_now = float(pos @ n)
        since = m.since_detect(obs.t)
        if m.n_detect > 0 and since <= p.lost_s + p.edge_s:
            if self.mode != "zig":
                self.mode = "zig"
                self.leg_hit = True
                center = m.centerline(obs.t, n)
                # Enter toward the centreline side.
                self.side = 1.0 if center is None or center >= c_now else -1.0
            self.sweep = None
            if new_det:
                self.leg_hit = True
            center = m.centerline(obs.t, n)
            off = 0.0 if center is None else (c_now - center) * self.side
            if (self.leg_hit and since >= p.edge_s) or off >= p.leg_max_half_width_m:
                self.side = -self.side
                self.leg_hit = False
            a = math.radians(p.angle_deg)
            return p.speed_m_s * (math.cos(a) * u + self.side * math.sin(a) * n), "zig"
        return self._lost_search(obs, u, n, "lost", p.lost_half_width_m, p.lost_growth, p.lost_max_half_width_m,
                                 p.lost_drift_m_s, p.lost_back_m)
