"""Accuracy figures of a wind estimate against the simulator's truth.

All inputs are sampled at the same instants ``t`` (s); winds are air-mass velocities NED
(m/s); directions are FROM-directions in degrees (see ``estimator.direction``).

Definitions (the numbers ``windseek estimate`` reports):
- evaluation window: t >= ``warmup_s`` (the cold start from zero wind with a large
  covariance is the convergence test, not part of the accuracy figures);
- "1-s average": trailing (causal) 1-s moving average, applied to the true total wind and
  to the estimate alike, as in anemometer intercomparisons (1-s means against 1-s means).
  Why not the instantaneous estimate against a centered average: with Kaimal turbulence
  (sigma_u = 1 m/s at 10 m/s) even a perfect causal low-pass of the *true* wind misses the
  centered 1-s mean by about 0.33 m/s horizontally, so that figure measures causality, not
  the estimator;
- RMSE per axis N, E, D of the instantaneous estimate against the total wind, and of the
  1-s average estimate against the 1-s average truth; horizontal RMSE = sqrt(N^2 + E^2);
- direction RMSE: from-direction of the 1-s average estimate against that of the 1-s
  average truth (wrapped differences); the Butterworth-filtered direction is reported
  against the same truth;
- coverage: fraction of (instant, axis) pairs with |estimate - total truth| <= 2 sigma (and
  <= 1 sigma: a Gaussian error would give 0.954 and 0.683);
- ``select``: an optional mask of instants (e.g. "near a building") the figures are taken over,
  after the averages were formed over the whole record (a 1-s mean still looks back 1 s);
- re-convergence: time after a wind step until the 3-D error of the 1-s averages drops
  below 1 m/s and stays below it for ``hold_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.direction import angle_diff_deg, from_direction_deg


def moving_average(t: np.ndarray, x: np.ndarray, window_s: float = 1.0, centered: bool = False) -> np.ndarray:
    """Moving average over ``window_s`` seconds of evenly sampled rows (K, ...), trailing
    (causal: the last ``window_s``) or centered."""
    if len(t) < 2:
        return x.copy()
    dt = float(np.median(np.diff(t)))
    n = max(1, int(round(window_s / dt)))
    if centered and n % 2 == 0:
        n += 1
    x2 = x.reshape(len(t), -1)
    c = np.cumsum(np.vstack([np.zeros((1, x2.shape[1])), x2]), axis=0)
    K = len(t)
    k = np.arange(K)
    # Shrink the window at the ends instead of padding (no invented samples).
    if centered:
        a = np.maximum(0, k - n // 2)
        b = np.minimum(K, k + n // 2 + 1)
    else:
        a = np.maximum(0, k - n + 1)
        b = k + 1
    out = (c[b] - c[a]) / (b - a)[:, None]
    return out.reshape(x.shape)


def reconvergence_time(
    t: np.ndarray, err_norm: np.ndarray, t_step: float, tol: float = 1.0, hold_s: float = 1.0
) -> float:
    """Seconds after ``t_step`` until ``err_norm`` < tol and stays so for ``hold_s`` (inf if never)."""
    idx = np.nonzero(t >= t_step)[0]
    if len(idx) == 0:
        return math.inf
    ok = err_norm[idx] < tol
    tt = t[idx]
    start = None
    for k in range(len(idx)):
        if ok[k]:
            if start is None:
                start = k
            if tt[k] - tt[start] >= hold_s:
                return float(tt[start] - t_step)
        else:
            start = None
    return math.inf


@dataclass
class Accuracy:
    """Figures of one run (see the module docstring)."""

    rmse_ms: tuple[float, float, float]  # vs total truth, N E D
    rmse_avg_ms: tuple[float, float, float]  # vs 1-s average, N E D
    rmse_horizontal_ms: float  # vs total truth
    rmse_horizontal_avg_ms: float  # vs 1-s average
    direction_rmse_deg: float  # vs 1-s average
    direction_filtered_rmse_deg: float  # Butterworth-filtered direction vs 1-s average
    coverage_2sigma: float
    coverage_2sigma_axis: tuple[float, float, float]
    reconverge_s: float | None  # None when the scenario has no step
    coverage_1sigma: float = math.nan
    samples: int = 0  # instants the figures are taken over

    def as_dict(self) -> dict[str, object]:
        r = lambda v: round(float(v), 4)  # noqa: E731
        return {
            "rmse_ms": {"N": r(self.rmse_ms[0]), "E": r(self.rmse_ms[1]), "D": r(self.rmse_ms[2])},
            "rmse_avg_ms": {"N": r(self.rmse_avg_ms[0]), "E": r(self.rmse_avg_ms[1]), "D": r(self.rmse_avg_ms[2])},
            "rmse_horizontal_ms": r(self.rmse_horizontal_ms),
            "rmse_horizontal_avg_ms": r(self.rmse_horizontal_avg_ms),
            "direction_rmse_deg": r(self.direction_rmse_deg),
            "direction_filtered_rmse_deg": r(self.direction_filtered_rmse_deg),
            "coverage_2sigma": r(self.coverage_2sigma),
            "coverage_2sigma_axis": [r(c) for c in self.coverage_2sigma_axis],
            "reconverge_s": None if self.reconverge_s is None else r(self.reconverge_s),
            "coverage_1sigma": r(self.coverage_1sigma),
            "samples": self.samples,
        }


def accuracy(
    t: np.ndarray,
    wind_est: np.ndarray,
    wind_sigma: np.ndarray,
    wind_true: np.ndarray,
    direction_filtered_deg: np.ndarray | None = None,
    warmup_s: float = 5.0,
    step_times: tuple[float, ...] = (),
    avg_window_s: float = 1.0,
    select: np.ndarray | None = None,
    true_avg: np.ndarray | None = None,
) -> Accuracy:
    """Accuracy of an estimate (K, 3) with 1-sigma (K, 3) against the true wind (K, 3).

    ``select`` (K,) bool: take the figures over these instants only (and t >= ``warmup_s``);
    ``true_avg`` (K, 3): the trailing ``avg_window_s`` mean of the truth when the caller formed
    it from finer samples than ``t`` (default: the moving average of ``wind_true``).
    """
    avg = moving_average(t, wind_true, avg_window_s) if true_avg is None else np.asarray(true_avg, dtype=float)
    avg_est = moving_average(t, wind_est, avg_window_s)
    m = t >= warmup_s
    if select is not None:
        m &= np.asarray(select, dtype=bool)
    e = wind_est[m] - wind_true[m]
    ea = avg_est[m] - avg[m]
    rmse = np.sqrt(np.mean(e**2, axis=0))
    rmse_a = np.sqrt(np.mean(ea**2, axis=0))
    d_est = from_direction_deg(avg_est[m, 0], avg_est[m, 1])
    d_true = from_direction_deg(avg[m, 0], avg[m, 1])
    d_rmse = float(np.sqrt(np.mean(angle_diff_deg(d_est, d_true) ** 2)))
    if direction_filtered_deg is not None:
        df_rmse = float(np.sqrt(np.mean(angle_diff_deg(direction_filtered_deg[m], d_true) ** 2)))
    else:
        df_rmse = math.nan
    inside = np.abs(e) <= 2.0 * wind_sigma[m]
    recon = None
    if step_times:
        err = np.linalg.norm(avg_est - avg, axis=1)
        recon = max(reconvergence_time(t, err, ts) for ts in step_times)
    cov_axis = np.mean(inside, axis=0)
    return Accuracy(
        rmse_ms=(float(rmse[0]), float(rmse[1]), float(rmse[2])),
        rmse_avg_ms=(float(rmse_a[0]), float(rmse_a[1]), float(rmse_a[2])),
        rmse_horizontal_ms=float(math.hypot(rmse[0], rmse[1])),
        rmse_horizontal_avg_ms=float(math.hypot(rmse_a[0], rmse_a[1])),
        direction_rmse_deg=d_rmse,
        direction_filtered_rmse_deg=df_rmse,
        coverage_2sigma=float(np.mean(inside)),
        coverage_2sigma_axis=(float(cov_axis[0]), float(cov_axis[1]), float(cov_axis[2])),
        reconverge_s=recon,
        coverage_1sigma=float(np.mean(np.abs(e) <= wind_sigma[m])),
        samples=int(np.count_nonzero(m)),
    )
