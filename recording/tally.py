"""Truth-based figures of a flight that a recorder tallies as it goes (simulation only).

:class:`FlightTally` takes the true vehicle position at every tick and the wind estimates with the
true wind at their time, and gives what the run summary needs: the horizontal path flown in
total, from the search start to the declaration (or the end), and until the vehicle first came
within :data:`~recording.summary.FOUND_RADIUS_M` of a true source; the start distance; the RMSE of
the wind estimate while airborne (true height above home over ``airborne_m``). SI, NED.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from recording.style import VecLike
from recording.summary import FOUND_RADIUS_M, RunSummary


class FlightTally:
    """Path lengths and wind error of one flight (see the module docstring)."""

    def __init__(self, sources_ned: Sequence[VecLike] | np.ndarray, airborne_m: float = 1.0) -> None:
        self.sources = np.asarray(sources_ned, dtype=float).reshape(-1, 3)[:, :2]
        self._sources_ne = [(float(n), float(e)) for n, e in self.sources]  # floats: tested at every tick
        self.airborne_m = airborne_m
        self.home: np.ndarray | None = None
        self.total_m = 0.0
        self.search_m = 0.0
        self.reach_m = math.nan
        self._prev: tuple[float, float, float] | None = None
        self._err2 = np.zeros(3)
        self.n_scored = 0

    def position(self, pos_ned: VecLike, armed: bool, searching: bool, declared: bool) -> None:
        """The true position [m] at a tick, with the phase: armed, searching, already declared."""
        p = (float(pos_ned[0]), float(pos_ned[1]), float(pos_ned[2]))  # a copy: callers pass live views
        if armed and self.home is None:
            self.home = np.array(p)
        prev = self._prev
        if prev is not None and armed:
            step = math.hypot(p[0] - prev[0], p[1] - prev[1])
            self.total_m += step
            if searching and not declared:
                self.search_m += step
                if math.isnan(self.reach_m) and any(math.hypot(p[0] - n, p[1] - e) <= FOUND_RADIUS_M
                                                    for n, e in self._sources_ne):  # fmt: skip
                    self.reach_m = self.search_m
        self._prev = p

    def wind(self, est_ned: VecLike, truth_ned: VecLike, height_m: float) -> None:
        """A wind estimate and the true wind at its time [m/s]; scored when ``height_m`` is airborne."""
        if height_m <= self.airborne_m:
            return
        d = [float(est_ned[k]) - float(truth_ned[k]) for k in range(3)]  # floats: ~10x cheaper than numpy here
        if all(math.isfinite(v) for v in d):
            for k in range(3):
                self._err2[k] += d[k] * d[k]
            self.n_scored += 1

    def rmse(self) -> np.ndarray | None:
        return np.sqrt(self._err2 / self.n_scored) if self.n_scored else None

    def fill(self, s: RunSummary) -> None:
        """Put the figures into a summary (fields already set are kept)."""
        if self.home is not None and len(self.sources) and s.start_distance_m is None:
            s.start_distance_m = round(float(np.min(np.hypot(*(self.sources - self.home[:2]).T))), 2)
        if s.total_path_m is None:
            s.total_path_m = round(self.total_m, 2)
        if s.search_path_m is None:
            s.search_path_m = round(self.search_m, 2)
        if s.reach_path_m is None and math.isfinite(self.reach_m):
            s.reach_path_m = round(self.reach_m, 2)
        r = self.rmse()
        if r is not None and s.wind_rmse_ned_m_s is None:
            s.wind_rmse_ned_m_s = [round(float(v), 3) for v in r]
            s.wind_rmse_horizontal_m_s = round(float(math.hypot(r[0], r[1])), 3)
            s.wind_scored = self.n_scored


__all__ = ["FlightTally"]
