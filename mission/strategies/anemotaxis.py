"""Anemotaxis (paper, Figs. 16-18): fly upwind on the low-pass filtered wind direction.

The heading command is the estimated wind from-direction through a Butterworth low-pass
(the wind source applies it; cutoff ``wind_filter_cutoff_hz``), so the vehicle turns with
the slow wind changes and not with turbulence. The chemical sensor only decides when to
stop: once the plume has been detected and then ends (the shared rule in
``mission.strategies.common``), the most-upwind detection is declared. There is no casting:
a vehicle that flies out of the plume sideways does not come back (that is what surge-cast
adds).

Without wind (``none``): there is no upwind direction; the vehicle flies along the heading
of the concentration gradient estimated from its own samples, starting from
``initial_heading_deg`` (seeded draw by default) -- a straight line until the gradient says
otherwise, i.e. a weak chemotaxis baseline.
"""

from __future__ import annotations

import numpy as np

from mission.strategies.base import Observation
from mission.strategies.common import BaseStrategy


class Anemotaxis(BaseStrategy):
    """Upwind flight on the filtered wind direction; declares where the plume ends."""

    name = "anemotaxis"

    def _search(self, obs: Observation, u: np.ndarray, n: np.ndarray, new_det: bool, dt: float
                ) -> tuple[np.ndarray, str]:
        state = "upwind" if self.memory.n_detect == 0 or self.memory.since_detect(obs.t) < self.p.lost_s \
            else "upwind-lost"
        return self.p.speed_m_s * u, state
