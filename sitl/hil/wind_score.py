"""One wind estimate stream scored against the truth: RMSE per estimate and of 1-s means, and how often
the stated uncertainty covers the error. Plain code, no I/O; :class:`sitl.hil.summary.TruthScore` keeps one
per source (windseek's estimator, the autopilot's own estimate).

- **RMSE** (N, E, D; m/s) over the airborne estimates, and again leaving out the first ``settle_s``
  after each lift-off (the filter's cold start).
- **RMSE of 1-s means**: the estimates and the truth at their times averaged over each whole second of
  simulation time, then compared (the paper's and the issue's figure: turbulence faster than 1 s is
  not a wind an estimator is asked for).
  The 1-s means are kept as a series (``series_1s``: second, estimate N E D, truth N E D) for figures
  such as the time to converge after a wind step.
- **Coverage**: the fraction of estimates whose horizontal error lies inside the stated 95 % circle
  (``var_horiz`` of WIND_COV split equally between N and E: radius^2 = 5.991 var_horiz / 2). None for
  an estimate without a covariance (ArduPilot's WIND).

Conventions: SI, NED, wind = air-mass velocity NED; simulation time in s.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

#: Seconds of 1-s means kept for the summary's series.
SERIES_MAX = 3600
#: chi-square 95 % quantile with 2 degrees of freedom (the horizontal error circle).
CHI2_95_2DOF = 5.991


class WindScore:
    """Accumulates one source's estimates against the truth (see the module docstring)."""

    def __init__(self, settle_s: float = 10.0) -> None:
        self.settle_s = float(settle_s)
        self.received = 0
        self.err2 = np.zeros(3)
        self.n = 0
        self.err2_settled = np.zeros(3)
        self.n_settled = 0
        self.covered = 0
        self.n_cov = 0
        self.last_estimate: list[float] | None = None
        self._bin: int | None = None
        self._bin_sum = np.zeros(6)
        self._bin_n = 0
        self.err2_1s = np.zeros(3)
        self.n_1s = 0
        #: [t of the second, mean estimate N E D, mean truth N E D] per scored second (the newest SERIES_MAX).
        self.series: deque[list[float]] = deque(maxlen=SERIES_MAX)

    def add(self, t: float, est: np.ndarray, truth: np.ndarray, since_lift_off_s: float,
            var_h: float | None = None) -> None:  # fmt: skip
        """One airborne estimate ``est`` at ``t`` [s] against the true wind ``truth`` (NED, m/s);
        ``var_h``: its stated horizontal variance (m^2/s^2, N + E), None when it states none."""
        e = est - truth
        self.err2 += e * e
        self.n += 1
        if since_lift_off_s >= self.settle_s:
            self.err2_settled += e * e
            self.n_settled += 1
        if var_h is not None and math.isfinite(var_h) and var_h > 0:
            self.n_cov += 1
            self.covered += int(e[0] ** 2 + e[1] ** 2 <= CHI2_95_2DOF * var_h / 2.0)
        b = int(math.floor(t))
        if b != self._bin:
            self._close_bin()
            self._bin = b
        self._bin_sum += np.concatenate((est, truth))
        self._bin_n += 1

    def _close_bin(self) -> None:
        if self._bin_n:
            m = self._bin_sum / self._bin_n
            d = m[:3] - m[3:]
            self.err2_1s += d * d
            self.n_1s += 1
            self.series.append([float(self._bin or 0), *(round(float(v), 3) for v in m)])
        self._bin_sum[:] = 0.0
        self._bin_n = 0

    def to_dict(self) -> dict[str, Any]:
        """The figures (rounded), with None for what was not measured."""
        self._close_bin()
        self._bin = None

        def rmse(e2: np.ndarray, n: int) -> list[float] | list[None]:
            return [round(float(v), 3) for v in np.sqrt(e2 / n)] if n else [None, None, None]

        r, r1 = rmse(self.err2, self.n), rmse(self.err2_1s, self.n_1s)
        return {"received": self.received, "scored": self.n, "rmse_ned_m_s": r,
                "rmse_horizontal_m_s": round(math.hypot(r[0], r[1]), 3) if self.n else None,  # type: ignore[arg-type]
                "rmse_ned_after_settle_m_s": rmse(self.err2_settled, self.n_settled),
                "scored_after_settle": self.n_settled, "rmse_1s_ned_m_s": r1,
                "rmse_1s_horizontal_m_s": round(math.hypot(r1[0], r1[1]), 3) if self.n_1s else None,  # type: ignore[arg-type]
                "seconds_scored": self.n_1s, "series_1s": list(self.series),
                "coverage_95_horizontal": round(self.covered / self.n_cov, 3) if self.n_cov else None,
                "last_estimate_ned_m_s": self.last_estimate}  # fmt: skip
