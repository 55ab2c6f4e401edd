"""What infotaxis shows of its source posterior: the map and the credible region, for the recorders.

:class:`PosteriorDisplay` is mixed into :class:`mission.strategies.infotaxis.Infotaxis`; the
recorders find these methods by name (``recording.trial``, ``recording.mission_rrd``). Frames and
units: NED (north, east) [m] relative to home.
"""

from __future__ import annotations

import math

import numpy as np

from mission.strategies.ste_filter import SourcePosterior


class PosteriorDisplay:
    """``posterior_map`` and ``credible_region`` over the strategy's ``post`` (module docstring)."""

    post: SourcePosterior
    declared: np.ndarray | None
    credible_radius: float

    def posterior_map(self, cell_m: float = 1.0, extent: tuple[float, float, float, float] | None = None
                      ) -> tuple[np.ndarray, tuple[float, float, float, float]] | None:
        """The source posterior at flight altitude for display: (P, extent) with ``P[i, j]`` the
        probability of cell i (north) x j (east), ``cell_m`` m square, ``extent`` = (north_min,
        north_max, east_min, east_max) [m NED, relative to home]; default extent: the prior box's
        bounding box. None before the first usable wind (no posterior yet)."""
        if not self.post.ready:
            return None
        if extent is None:
            extent = self._prior_extent()
        return self.post.posterior_map(cell_m, extent)

    def credible_region(self) -> tuple[np.ndarray, float] | None:
        """(centre (north, east) [m NED], radius [m]) of the current ``credible_level`` disc (the
        declared one after the declaration); None before the posterior exists."""
        if not self.post.ready:
            return None
        c = self.declared[0:2].copy() if self.declared is not None else self.post.mean_ne()
        return c, float(self.credible_radius)

    def _prior_extent(self) -> tuple[float, float, float, float]:
        box = self.post.prior
        r = math.hypot(max(box.ahead, box.back), box.half_width if box.delta_sigma is not None else box.ahead)
        o = box.origin_ne
        return (math.floor(o[0] - r), math.ceil(o[0] + r), math.floor(o[1] - r), math.ceil(o[1] + r))
