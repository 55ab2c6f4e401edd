"""Source posterior of the STE strategy: a regularized particle filter over the source term.

State of one particle (a source hypothesis): horizontal position (n, e) [m, NED, relative to
home], height h [m above the ground], effective release rate q [g/s] (see
``mission.strategies.ste_model``) and the plume direction offset delta [rad] from the filtered
wind direction. The source does not move, so there is no prediction step: every reading (hit or
miss, ``update``) multiplies the weights by its likelihood raised to the tempering exponent
(correlated readings, see ``InfotaxisParams.tempering``). When the effective sample size falls
below half the particles they are resampled (systematic) and jittered with a Gaussian kernel of
``jitter`` times the posterior's spread per dimension, floored: the regularized particle filter
(Musso, Oudjane & Le Gland 2001) as used for source-term estimation by Ristic et al. 2016
("Source term estimation of a hazardous airborne release using an unmanned aerial vehicle") and
Hutchinson, Liu & Chen (AutoSTE). Heights and rates are reflected into their prior range.

The prior is uniform over a box in the frame of the first usable wind (``prior_back_m``
downwind to ``prior_range_m`` upwind of the first position, ``prior_half_width_m`` either side),
uniform heights, log-uniform rates, a Gaussian direction offset of ``direction_sigma_deg``
(without wind information: any direction, the box becomes a square about the start).

Every random draw comes from the ``numpy`` generator given at construction (seeded by the trial).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mission.strategies.ste_history import ReadingHistory
from mission.strategies.ste_model import accumulate, expected_information, fold, meander_nodes, meander_of
from mission.strategies.ste_urban import UrbanModel, accumulate_urban, is_solid
from mission.strategies.ste_urban_plan import urban_information

#: Resampled particles whose history likelihood sets the scale of the redrawn ones' (``weigh_step``).
WEIGH_REFERENCE = 20
#: Meander nodes of the history replay (3 instead of 7: log-likelihoods correlate 0.995, a third of the cost).
REPLAY_NODES = 3

#: Smallest kernel standard deviation after resampling per dimension: position [m], height [m],
#: log10 rate, direction [rad] (a collapsed cloud must still be able to move a little).
JITTER_FLOOR = (0.15, 0.05, 0.02, math.radians(0.3))


@dataclass(frozen=True)
class PriorBox:
    """The prior: a box in the (upwind, crosswind) frame of ``upwind_rad`` about ``origin_ne``
    [m], ``back`` m downwind to ``ahead`` m upwind, ``half_width`` m either side; heights [m],
    rates [g/s], direction sigma [rad] (None: uniform direction, square box of side
    2 * ``ahead`` about the origin)."""

    origin_ne: tuple[float, float]
    upwind_rad: float
    ahead: float
    back: float
    half_width: float
    h_range: tuple[float, float]
    q_range: tuple[float, float]
    delta_sigma: float | None


class _Cloud:
    """One weighted particle set over (n, e, h, log10 q, delta) with its meander-window state."""

    def __init__(self, pn: np.ndarray, pe: np.ndarray, h: np.ndarray, lq: np.ndarray, delta: np.ndarray,
                 n_nodes: int) -> None:
        self.set(pn, pe, h, lq, delta, n_nodes)

    def set(self, pn: np.ndarray, pe: np.ndarray, h: np.ndarray, lq: np.ndarray, delta: np.ndarray,
            n_nodes: int) -> None:
        """New particles, equal weights, empty window."""
        n = len(pn)
        self.pn, self.pe, self.h, self.lq, self.delta = pn, pe, h, lq, delta
        self.q = 10.0**lq
        self.cd = np.cos(delta)
        self.sd = np.sin(delta)
        self.logw = np.zeros(n)
        self.acc = np.zeros((n, n_nodes))
        self.alpha = np.full((n, n_nodes), -1.0)
        self._lw = np.zeros(n)
        self.w = np.full(n, 1.0 / n)

    def add(self, post: SourcePosterior, px: float, py: float, pz: float, hit: bool, cphi: float, sphi: float,
            u: float, path: tuple[np.ndarray, int] | None = None) -> None:
        """Accumulate one reading into the window and refresh the normalized weights ``w``; with
        a backward ``path`` (points, count) through the urban likelihood (``ste_urban``)."""
        if path is not None and post.urban is not None:
            gp, _, _, solid = post.urban.plane.args()
            accumulate_urban(self.acc, self.alpha, self.pn, self.pe, self.h, self.q, self.cd, self.sd, path[0],
                             path[1], pz, hit, post.kappa, post.rho, post.nodes, post.mc, gp, solid,
                             post.urban.mix_rate)
        else:
            accumulate(self.acc, self.alpha, self.pn, self.pe, self.h, self.q, self.cd, self.sd, px, py, pz, cphi,
                       sphi, u, hit, post.kappa, post.rho, post.nodes, post.mc)
        best = fold(self.logw, self.acc, post.log_wts, self._lw)
        w = np.exp(self._lw - best)
        self.w = w / w.sum()

    def end_window(self, log_wts: np.ndarray) -> None:
        """Fold the window's meander-marginal likelihood into the log weights; new window."""
        best = fold(self.logw, self.acc, log_wts, self._lw)
        self.logw = self._lw - best
        self.acc[:] = 0.0
        self.alpha[:] = -1.0

    def ess(self) -> float:
        return 1.0 / float(self.w @ self.w)


class SourcePosterior:
    """Weighted particles over (n, e, h, log10 q, delta); see the module docstring."""

    def __init__(self, n_particles: int, mc: np.ndarray, tempering: float, jitter: float,
                 rng: np.random.Generator, meander_nodes_n: int = 7, window_s: float = 8.0,
                 persistence: float = 0.5, rejuvenate: float = 0.0, corridor: tuple[float, float] = (25.0, 8.0),
                 weigh_rejuvenated: bool = False) -> None:
        self.n = int(n_particles)
        self.weigh_rejuvenated = bool(weigh_rejuvenated)
        self.history = ReadingHistory()
        self.replay_nodes, self.replay_log_wts = meander_nodes(REPLAY_NODES)
        self._pending: np.ndarray | None = None  # redrawn particles still to weigh
        self._pending_rows = 0
        self._typical = math.nan
        self.version = 0  # changes with every reading
        self.rejuvenate = float(rejuvenate)
        self.corridor = corridor
        self.mc = mc
        self.kappa = float(tempering)
        self.jitter = float(jitter)
        self.rng = rng
        self.nodes, self.log_wts = meander_nodes(meander_nodes_n)
        self.window_s = float(window_s)
        self.t_window = math.nan
        self.rho = float(persistence)
        self._prior: PriorBox | None = None
        self._main: _Cloud | None = None
        self.urban: UrbanModel | None = None
        self.n_fallback = 0  # urban readings weighed with the open-field plume (position inside a building)
        self.n_updates = 0
        self.n_resamples = 0

    # ------------------------------------------------------------------ prior
    def _draw_prior(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        rng, box = self.rng, self.prior
        if box.delta_sigma is None:
            a = rng.uniform(-box.ahead, box.ahead, n)
            c = rng.uniform(-box.ahead, box.ahead, n)
            delta = rng.uniform(-math.pi, math.pi, n)
            ux, uy = 1.0, 0.0
        else:
            a = rng.uniform(-box.back, box.ahead, n)
            c = rng.uniform(-box.half_width, box.half_width, n)
            delta = rng.normal(0.0, box.delta_sigma, n)
            ux, uy = math.cos(box.upwind_rad), math.sin(box.upwind_rad)
        pn = box.origin_ne[0] + a * ux - c * uy
        pe = box.origin_ne[1] + a * uy + c * ux
        h = rng.uniform(box.h_range[0], box.h_range[1], n)
        lq = rng.uniform(math.log10(box.q_range[0]), math.log10(box.q_range[1]), n)
        return pn, pe, h, lq, delta

    def init_prior(self, box: PriorBox) -> None:
        """Draw the particles from the prior ``box``; equal weights."""
        self._prior = box
        self._main = _Cloud(*self._draw_prior(self.n), len(self.nodes))

    @property
    def ready(self) -> bool:
        return self._prior is not None

    @property
    def prior(self) -> PriorBox:
        if self._prior is None:
            raise RuntimeError("SourcePosterior: init_prior() must be called first")
        return self._prior

    @property
    def main(self) -> _Cloud:
        if self._main is None:
            raise RuntimeError("SourcePosterior: init_prior() must be called first")
        return self._main

    # views of the main set, for the summaries
    pn = property(lambda self: self.main.pn)
    pe = property(lambda self: self.main.pe)
    h = property(lambda self: self.main.h)
    lq = property(lambda self: self.main.lq)
    q = property(lambda self: self.main.q)
    delta = property(lambda self: self.main.delta)
    w = property(lambda self: self.main.w)

    def set_urban(self, model: UrbanModel | None) -> None:
        """Weigh the next readings with the urban likelihood over ``model`` (None: the open field)."""
        self.urban = model
        if model is not None:
            gp, _, _, solid = model.plane.args()
            self.history.set_urban(gp, solid, model.mix_rate)

    def _path(self, px: float, py: float) -> tuple[np.ndarray, int] | None:
        """The reading's backward path with the urban model; None (the open-field plume) without it or
        for a reading inside a building (the known layout does not match the flight)."""
        if self.urban is None:
            return None
        gp, _, _, solid = self.urban.plane.args()
        if is_solid(gp, solid, px, py):
            self.n_fallback += 1
            return None
        paths, lens = self.urban.paths(np.array([px]), np.array([py]))
        return paths[0], int(lens[0])

    # ------------------------------------------------------------------ update
    def update(self, t: float, px: float, py: float, pz: float, hit: bool, downwind_rad: float, u: float) -> None:
        """One reading at time ``t`` [s]: hit (True) or miss at horizontal (px, py) [m NED],
        height pz [m], with the mean plume travelling along ``downwind_rad`` [rad] at ``u`` m/s.

        The meander is a random effect shared by the readings of one window of ``window_s``:
        their log-likelihoods are summed per meander node (``acc``) and the nodes marginalized
        when the weights are needed; at the end of a window the marginal is folded into the log
        weights and a new window starts."""
        while self._pending is not None:  # normally done on the ticks between two readings
            self.weigh_step(self.n)
        if math.isnan(self.t_window) or t - self.t_window >= self.window_s:
            self._end_window()
            self.t_window = t
        cphi, sphi = math.cos(downwind_rad), math.sin(downwind_rad)
        path = self._path(px, py)
        self.main.add(self, px, py, pz, hit, cphi, sphi, u, path)
        self.history.add(t, px, py, pz, hit, cphi, sphi, u, self.kappa, meander_of(self.mc),
                         None if path is None else path[0], 0 if path is None else path[1])
        self.n_updates += 1
        self.version += 1
        if self.main.ess() < 0.5 * self.n:
            self._end_window()
            self.t_window = t
            self._resample()

    def _end_window(self) -> None:
        """Fold the current window's meander-marginal likelihood into the log weights."""
        if self.n_updates == 0:
            return
        self.main.end_window(self.log_wts)

    def _resample(self) -> None:
        """Systematic resampling, then a Gaussian kernel jitter (regularized particle filter)."""
        rng, n, m = self.rng, self.n, self.main
        cols = [m.pn, m.pe, m.h, m.lq, m.delta]
        idx = _systematic(m.w, n, rng)
        sig = [self.jitter * math.sqrt(max(float(m.w @ (x - m.w @ x) ** 2), 0.0)) for x in cols]
        floors = (JITTER_FLOOR[0], JITTER_FLOOR[0], JITTER_FLOOR[1], JITTER_FLOOR[2], JITTER_FLOOR[3])
        pn, pe, h, lq, delta = [x[idx] + max(s, f) * rng.standard_normal(n) for x, s, f in
                                zip(cols, sig, floors, strict=True)]
        k = int(round(self.rejuvenate * n))
        sel = self._rejuvenate(k, np.array([m.w @ m.pn, m.w @ m.pe]), pn, pe, h, lq, delta) if k > 0 else None
        box = self.prior
        h = _reflect(h, *box.h_range)
        lq = _reflect(lq, math.log10(box.q_range[0]), math.log10(box.q_range[1]))
        m.set(pn, pe, h, lq, delta, len(self.nodes))
        if sel is not None and self.weigh_rejuvenated and len(self.history):
            self._pending, self._pending_rows, self._typical = sel, len(self.history), math.nan
        self.n_resamples += 1

    def weigh_step(self, max_particles: int) -> bool:
        """Weigh up to ``max_particles`` of the particles redrawn at the last resampling against
        every reading before it (``ste_history``; spread over the ticks between two readings, the
        strategy's CPU budget). Each enters with its history likelihood over the typical resampled
        particle's (log-mean-exp of ``WEIGH_REFERENCE`` of them, weighed first), at most 1: a
        redrawn particle may come back as likely as the set's, not push it out in one step.
        Returns True when the weights changed (by at most the redrawn particles' share of the mass:
        the summaries wait for the next reading, ``version`` is not changed)."""
        if self._pending is None:
            return False
        m = self.main
        if math.isnan(self._typical):
            rest = np.setdiff1d(np.arange(self.n), self._pending)
            ref = self.rng.choice(rest, size=min(WEIGH_REFERENCE, len(rest)), replace=False)
            lr = self._replay(ref)
            self._typical = float(lr.max() + np.log(np.mean(np.exp(lr - lr.max()))))
            max_particles -= len(ref)
            if max_particles <= 0:
                return False
        chunk, rest_sel = self._pending[:max_particles], self._pending[max_particles:]
        self._pending = rest_sel if len(rest_sel) else None
        m.logw[chunk] = np.minimum(self._replay(chunk) - self._typical, 0.0)
        w = np.exp(m.logw - m.logw.max())
        m.w = w / w.sum()
        return True

    def _replay(self, idx: np.ndarray) -> np.ndarray:
        """History log-likelihood (readings before the last resampling) of the particles ``idx``."""
        m = self.main
        return self.history.log_likelihood((m.pn[idx], m.pe[idx], m.h[idx], m.q[idx], m.cd[idx], m.sd[idx]),
                                           self.mc, self.replay_nodes, self.replay_log_wts, self.rho,
                                           self.window_s, self._pending_rows)

    def _rejuvenate(self, k: int, c: np.ndarray, pn: np.ndarray, pe: np.ndarray, h: np.ndarray, lq: np.ndarray,
                    delta: np.ndarray) -> np.ndarray:
        """Redraw ``k`` of the resampled particles (in place) from the prior restricted to a corridor
        about the posterior mean ``c``: ``corridor[0]`` m up- and downwind, ``corridor[1]`` m either
        side (along the first wind's axis). A particle filter cannot get back a region it has lost
        (no particle is left there to weigh); these few can, if the readings come to favour it
        (e.g. a dense burst of far-field hits made a place downwind of the source look like its
        end). Cf. "roughening" (Gordon, Salmond & Smith 1993)."""
        rng, box = self.rng, self.prior
        sel = rng.choice(self.n, size=k, replace=False)
        a = rng.uniform(-self.corridor[0], self.corridor[0], k)
        b = rng.uniform(-self.corridor[1], self.corridor[1], k)
        ux, uy = math.cos(box.upwind_rad), math.sin(box.upwind_rad)
        pn[sel] = c[0] + a * ux - b * uy
        pe[sel] = c[1] + a * uy + b * ux
        h[sel] = rng.uniform(box.h_range[0], box.h_range[1], k)
        lq[sel] = rng.uniform(math.log10(box.q_range[0]), math.log10(box.q_range[1]), k)
        if box.delta_sigma is not None:
            delta[sel] = rng.normal(0.0, box.delta_sigma, k)
        return sel

    # ------------------------------------------------------------------ summaries
    def mean_ne(self) -> np.ndarray:
        """Posterior mean of the horizontal source position (north, east) [m]."""
        return np.array([self.w @ self.pn, self.w @ self.pe])

    def mean_height(self) -> float:
        """Posterior mean source height [m above ground]."""
        return float(self.w @ self.h)

    def credible_radius(self, level: float, center: np.ndarray | None = None) -> float:
        """Radius [m] of the horizontal disc about ``center`` (default the mean) holding
        ``level`` of the posterior probability."""
        c = self.mean_ne() if center is None else center
        d = np.hypot(self.pn - c[0], self.pe - c[1])
        order = np.argsort(d)
        cum = np.cumsum(self.w[order])
        k = min(int(np.searchsorted(cum, level)), self.n - 1)
        return float(d[order[k]])

    def credible_disc(self, level: float, iterations: int = 4) -> tuple[np.ndarray, float]:
        """A small horizontal disc holding ``level`` of the posterior: (centre (north, east) [m],
        radius [m]). Starting from the mean, the centre moves to the mean of the particles inside
        the current disc (a mean shift toward the mode: the posterior is skewed, with a tail
        upwind along the plume), and the smallest disc found is kept."""
        c = self.mean_ne()
        best_c, best_r = c, self.credible_radius(level, c)
        for _ in range(iterations):
            d = np.hypot(self.pn - c[0], self.pe - c[1])
            inside = d <= best_r
            w = self.w[inside]
            if w.sum() <= 0.0:
                break
            c = np.array([w @ self.pn[inside], w @ self.pe[inside]]) / w.sum()
            r = self.credible_radius(level, c)
            if r < best_r:
                best_c, best_r = c, r
        return best_c, best_r

    def mass_within(self, center: np.ndarray, radius_m: float) -> float:
        """Posterior probability that the source lies within ``radius_m`` of ``center`` (horizontal)."""
        d = np.hypot(self.pn - center[0], self.pe - center[1])
        return float(self.w[d <= radius_m].sum())

    def ess(self) -> float:
        """Effective sample size of the main set."""
        return self.main.ess()

    # ------------------------------------------------------------------ planning
    def planning_set(self, m: int) -> tuple[np.ndarray, ...]:
        """``m`` equally weighted particles drawn systematically from the posterior:
        (n, e, h, q, cos delta, sin delta). (A fixed offset instead of a random one, so that the
        same posterior gives the same set, made the moves worse on the development seeds: reach
        ratio 2.32 instead of 1.66.)"""
        c = self.main
        idx = _systematic(c.w, min(m, self.n), self.rng)
        return c.pn[idx], c.pe[idx], c.h[idx], c.q[idx], c.cd[idx], c.sd[idx]

    def information(self, cx: np.ndarray, cy: np.ndarray, pz: float, downwind_rad: float, u: float,
                    plan: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Expected information [bits] of one reading at each point (cx, cy) [m NED], height pz,
        over the planning set ``plan``; and the predicted hit probability there."""
        info = np.empty(len(cx))
        phit = np.empty(len(cx))
        pn, pe, h, q, cd, sd = plan
        if self.urban is not None:
            return urban_information(self.urban, cx, cy, pz, plan, self.mc)
        expected_information(np.ascontiguousarray(cx, dtype=float), np.ascontiguousarray(cy, dtype=float), pz,
                             pn, pe, h, q, cd, sd, math.cos(downwind_rad), math.sin(downwind_rad), u, self.mc,
                             info, phit)
        return info, phit

    # ------------------------------------------------------------------ display
    def posterior_map(self, cell_m: float = 1.0, extent: tuple[float, float, float, float] | None = None
                      ) -> tuple[np.ndarray, tuple[float, float, float, float]]:
        """The horizontal posterior on a grid: (P, extent). ``P[i, j]`` is the probability that the
        source lies in cell i (north) x j (east) of ``cell_m`` metres; ``extent`` = (north_min,
        north_max, east_min, east_max) [m NED], by default the bounding box of the particles
        (rounded out to whole cells)."""
        if extent is None:
            extent = (math.floor(self.pn.min()), math.ceil(self.pn.max()) + cell_m,
                      math.floor(self.pe.min()), math.ceil(self.pe.max()) + cell_m)
        n0, n1, e0, e1 = extent
        bins = (max(1, round((n1 - n0) / cell_m)), max(1, round((e1 - e0) / cell_m)))
        grid, _, _ = np.histogram2d(self.pn, self.pe, bins=bins, range=((n0, n1), (e0, e1)), weights=self.w)
        return grid, (float(n0), float(n1), float(e0), float(e1))


def _systematic(w: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """``m`` indices drawn systematically from the normalized weights ``w``."""
    idx = np.searchsorted(np.cumsum(w), (rng.random() + np.arange(m)) / m)
    return np.minimum(idx, len(w) - 1)


def _reflect(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``x`` reflected at the bounds into [lo, hi] (one reflection, then clipped)."""
    if hi <= lo:
        return np.full_like(x, lo)
    x = np.where(x < lo, 2 * lo - x, x)
    x = np.where(x > hi, 2 * hi - x, x)
    return np.clip(x, lo, hi)
