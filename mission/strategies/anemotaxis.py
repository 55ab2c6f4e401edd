"""Anemotaxis (paper, Figs. 16-18): fly upwind on the low-pass filtered wind direction.

The heading command is the estimated wind from-direction through a Butterworth low-pass
(the wind source applies it; cutoff ``wind_filter_cutoff_hz``), so the vehicle turns with
the slow wind changes and not with turbulence. The chemical sensor only decides when to
stop: once the plume has been detected and then ends (the shared rule in
``mission.strategies.common``), the most-upwind detection is declared.

Lost-plume recovery (issue 19): the paper's anemotaxis has none, and a vehicle that left the
plume sideways flew upwind until the geofence (13-29 of 50 trials). Now, when the plume has
been lost for ``lost_s`` and no verification of a plume end is due, the vehicle casts
crosswind about the last hits' centreline with a growing half-width (``recover_*``), drifting
back downwind of the last hit, until it detects again (then upwind again) -- and gives up
(``state = "give-up"``, done, nothing declared) when it has been lost for ``give_up_s``, or,
before any detection, when it is ``max_range_m`` from home. A search ends in a declaration or
a clear give-up, not at the fence.

Without wind (``none``): there is no upwind direction; the vehicle flies along the heading
of the concentration gradient estimated from its own samples, starting from
``initial_heading_deg`` (seeded draw by default) -- a straight line until the gradient says
otherwise, i.e. a weak chemotaxis baseline.
"""

from __future__ import annotations

import numpy as np

from mission.strategies.base import Observation, Setpoint
from mission.strategies.common import BaseStrategy
from mission.strategies.params import AnemotaxisParams


class Anemotaxis(BaseStrategy):
    """Upwind flight on the filtered wind direction; declares where the plume ends; casts back
    downwind when the plume is lost; gives up when it stays lost."""

    name = "anemotaxis"
    p: AnemotaxisParams

    def _search(self, obs: Observation, u: np.ndarray, n: np.ndarray, new_det: bool, dt: float
                ) -> tuple[np.ndarray, str]:
        p = self.p
        m = self.memory
        if m.n_detect == 0 or m.since_detect(obs.t) < p.lost_s:
            self.sweep = None
            return p.speed_m_s * u, "upwind"
        return self._lost_search(obs, u, n, "recover", p.recover_half_width_m, p.recover_growth,
                                 p.recover_max_half_width_m, p.recover_drift_m_s, p.recover_back_m)

    def update(self, obs: Observation) -> Setpoint:
        sp = super().update(obs)
        if sp.declared_source_ned is not None or self.p is None:
            return sp
        p = self.p
        m = self.memory
        lost_long = m.n_detect > 0 and m.since_detect(obs.t) >= p.give_up_s
        too_far = m.n_detect == 0 and float(np.hypot(*(obs.position_ned[0:2] - self.start[0:2]))) >= p.max_range_m
        if lost_long or too_far:
            # Give up: hold here, nothing declared (the runner lands).
            hold = np.array([obs.position_ned[0], obs.position_ned[1], self.start[2] - p.altitude_m])
            return Setpoint(position_ned=hold, velocity_ned=np.zeros(3), yaw_rad=sp.yaw_rad, done=True,
                            state="give-up", info=dict(sp.info))
        return sp
