"""Every reading the STE posterior has weighed, kept to weigh new hypotheses against all of them.

A particle filter cannot get back a region it has lost, so at each resampling a few particles are
redrawn from the prior near the posterior (``SourcePosterior._rejuvenate``). Entered with the
resampled particles' equal weight, such a particle had not been weighed against the readings so
far: a hypothesis the early misses had ruled out came back fresh and, with the next burst of hits
beside it, won (open-field-high, development seed 101: 120 s without hits at the start, then a
burst 56 m downwind of the source declared at a stated confidence of 0.92). Here each redrawn
particle is weighed against the whole history, as are as many of the resampled ones; the redrawn
one then enters with the likelihood ratio to the typical resampled particle: a place the readings
ruled out stays out, one they favour (a source the particle set lost, development seed 100) comes
back with the weight it deserves.

The replay uses the posterior's own kernels (``ste_model.accumulate`` and ``fold``) with each
reading's own tempering and meander (they adapt to the measured conditions, ``ste_adapt``) and
meander windows of ``window_s`` from the first reading. A reading weighed with the urban likelihood
(``ste_urban``) keeps its backward path and is replayed with it; one without (the open-field model,
or an urban reading that fell back to it) with the open-field plume. Units SI, NED (north, east) [m].
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mission.strategies.ste_model import MTH2 as _MTH2
from mission.strategies.ste_model import accumulate, fold
from mission.strategies.ste_urban import PATH_COLS, accumulate_urban

#: Empty path storage of a history without urban readings (the kernel's arguments).
_NO_PATHS = np.zeros((0, 1, PATH_COLS))
_NO_LENS = np.zeros(0, dtype=np.int64)
_NO_GP = np.zeros(8)
_NO_SOLID = np.zeros((1, 1), dtype=np.uint8)

# Columns of one stored reading.
_T, _PX, _PY, _PZ, _HIT, _C, _S, _U, _K, _M = range(10)


class ReadingHistory:
    """The readings (bins) a posterior has weighed, with the model settings each was weighed with."""

    def __init__(self) -> None:
        self._rows: list[tuple[float, ...]] = []
        self._paths = _NO_PATHS
        self._lens = _NO_LENS
        self._urban: tuple[np.ndarray, np.ndarray, float] | None = None  # gp, solid, mix_rate

    def set_urban(self, gp: np.ndarray, solid: np.ndarray, mix_rate: float) -> None:
        """The urban slice the stored paths are weighed in (``ste_urban``)."""
        self._urban = (gp, solid, float(mix_rate))

    def _store_path(self, path: np.ndarray | None, k_len: int) -> None:
        """Row ``len - 1``'s backward path (none, or k_len 0: the open-field model)."""
        if self._urban is None:
            return
        n = len(self._rows)
        if len(self._lens) < n:
            kmax = max(self._paths.shape[1], path.shape[0] if path is not None else 1)
            paths = np.zeros((max(64, 2 * n), kmax, PATH_COLS))
            paths[: self._paths.shape[0], : self._paths.shape[1]] = self._paths
            lens = np.zeros(len(paths), dtype=np.int64)
            lens[: len(self._lens)] = self._lens
            self._paths, self._lens = paths, lens
        k = k_len if path is not None else 0
        if path is not None and k > 0:
            self._paths[n - 1, :k] = path[:k]
        self._lens[n - 1] = k

    def __len__(self) -> int:
        return len(self._rows)

    def add(self, t: float, px: float, py: float, pz: float, hit: bool, cphi: float, sphi: float, u: float,
            kappa: float, meander_rad: float, path: np.ndarray | None = None, k_len: int = 0) -> None:
        """One reading at ``t`` [s], (px, py) [m NED], height pz [m], plume heading (cos, sin),
        wind ``u`` [m/s], weighed with tempering ``kappa`` and meander sigma ``meander_rad``; with
        the urban likelihood its backward ``path`` of ``k_len`` points."""
        self._rows.append((t, px, py, pz, 1.0 if hit else 0.0, cphi, sphi, u, kappa, meander_rad))
        self._store_path(path, k_len)

    def log_likelihood(self, particles: tuple[np.ndarray, ...], mc: np.ndarray, nodes: np.ndarray,
                       log_wts: np.ndarray, rho: float, window_s: float, n_rows: int | None = None) -> np.ndarray:
        """Tempered log-likelihood of the first ``n_rows`` (default all) stored readings for each
        particle (n, e, h, q, cos delta, sin delta), the meander marginalized per window of
        ``window_s`` [s] over ``nodes`` (Gauss-Hermite, log weights ``log_wts``)."""
        rows = np.array(self._rows[:n_rows], dtype=np.float64).reshape(-1, 10)
        pn, pe, h, q, cd, sd = (np.ascontiguousarray(a, dtype=np.float64) for a in particles)
        gp, solid, mix = self._urban if self._urban is not None else (_NO_GP, _NO_SOLID, 0.0)
        return _replay(rows, pn, pe, h, q, cd, sd, mc.copy(), nodes, log_wts, rho, window_s, self._paths,
                       self._lens, gp, solid, mix)


@njit(cache=True)
def _replay(rows: np.ndarray, pn: np.ndarray, pe: np.ndarray, h: np.ndarray, q: np.ndarray, cd: np.ndarray,
            sd: np.ndarray, mc: np.ndarray, nodes: np.ndarray, log_wts: np.ndarray, rho: float, window_s: float,
            paths: np.ndarray, lens: np.ndarray, gp: np.ndarray, solid: np.ndarray, mix_rate: float) -> np.ndarray:
    """The history's log-likelihood per particle (see ``ReadingHistory.log_likelihood``); row k
    with ``lens[k] > 0`` is weighed along its backward path ``paths[k]``."""
    m = pn.shape[0]
    logw = np.zeros(m)
    acc = np.zeros((m, nodes.shape[0]))
    alpha = np.full((m, nodes.shape[0]), -1.0)
    out = np.empty(m)
    t0 = -np.inf
    for k in range(rows.shape[0]):
        r = rows[k]
        if r[_T] - t0 >= window_s:
            if k > 0:
                fold(logw, acc, log_wts, out)
                logw[:] = out
                acc[:] = 0.0
                alpha[:] = -1.0
            t0 = r[_T]
        mc[_MTH2] = r[_M] * r[_M]
        if k < lens.shape[0] and lens[k] > 0:
            accumulate_urban(acc, alpha, pn, pe, h, q, cd, sd, paths[k], lens[k], r[_PZ], r[_HIT] > 0.5, r[_K], rho,
                             nodes, mc, gp, solid, mix_rate)
        else:
            accumulate(acc, alpha, pn, pe, h, q, cd, sd, r[_PX], r[_PY], r[_PZ], r[_C], r[_S], r[_U], r[_HIT] > 0.5,
                       r[_K], rho, nodes, mc)
    if rows.shape[0] > 0:
        fold(logw, acc, log_wts, out)
        logw[:] = out
    return logw
