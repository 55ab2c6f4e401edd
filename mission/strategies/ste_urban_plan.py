"""The urban likelihood's move-choice kernel: expected information of candidate readings.

The move choice (``Infotaxis._plan``) scores ``plan_directions`` x ``plan_points`` candidate reading
points over ``plan_particles`` particles (160 x 300 by default): each candidate's backward path
(``ste_urban.backward_paths``) and, for every particle, the particle's place in that path's frame
(``ste_urban.path_frame``) and the mean plume's hit probability there. It is the strategy's most
expensive tick (issue 32's speed goal: the worst tick within 5 ms on one core at 10 Hz).

The numbers are those of the per-pair formulation (the same operations in the same order: the move
choice is bit-identical to it, ``tests/test_ste_urban.py`` checks it); only the work is arranged
for speed:

- the coarse stage of ``path_frame`` (the closest of every ``COARSE``-th path point) runs for all
  particles of one path at once, a branch-free loop over particles the compiler vectorizes
  (``ste_urban.coarse_closest``; the update does the same), and its result is handed to
  ``ste_urban.frame_about``;
- the path frame is found once per pair, for both the far test and the plume (it was found twice);
- whether a particle lies inside a building is looked up once per particle, not once per pair.

Units SI; frame local NED (north, east) [m]; information in bits.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mission.strategies.ste_model import EPS, binary_entropy, mean_plume_prob
from mission.strategies.ste_urban import (
    UrbanModel,
    coarse_closest,
    frame_about,
    is_solid,
    near_path,
    path_frame,
    plume_in_path_frame,
)


@njit(cache=True)
def expected_information_urban(paths: np.ndarray, lens: np.ndarray, pz: float, n: np.ndarray, e: np.ndarray,
                               h: np.ndarray, q: np.ndarray, cd: np.ndarray, sd: np.ndarray, mc: np.ndarray,
                               gp: np.ndarray, solid: np.ndarray, mix_rate: float, out_info: np.ndarray,
                               out_phit: np.ndarray) -> None:
    """``ste_model.expected_information`` at candidate points whose backward paths are ``paths[k,
    :lens[k]]`` (sensor height pz [m]), over equally weighted particles (n, e [m NED], h [m], q [g/s],
    cos / sin of the direction offset): mutual information [bits] into ``out_info[k]`` and the
    predicted hit probability into ``out_phit[k]``. A source inside a building, or far from the path
    (``ste_urban.near_path``), gives eps."""
    m = n.shape[0]
    inside = np.empty(m, dtype=np.bool_)
    for i in range(m):
        inside[i] = is_solid(gp, solid, n[i], e[i])
    best = np.empty(m)
    kc = np.zeros(m, dtype=np.int64)
    for k in range(paths.shape[0]):
        path = paths[k]
        k_len = lens[k]
        if k_len >= 2:
            coarse_closest(path, k_len, n, e, best, kc)
        pbar = 0.0
        hbar = 0.0
        for i in range(m):
            p = mc[EPS]
            if not inside[i]:
                if k_len >= 2:
                    x0, y0, tau, mix = frame_about(path, k_len, n[i], e[i], kc[i], best[i])
                else:
                    x0, y0, tau, mix = path_frame(path, k_len, n[i], e[i], gp[5], gp[6])
                if near_path(x0, y0, mix, cd[i], sd[i], mix_rate, mc):
                    y, g, cpk, sm, si2 = plume_in_path_frame(x0, y0, tau, mix, cd[i], sd[i], pz, h[i], q[i], gp,
                                                             mix_rate, mc)
                    p = mean_plume_prob(y, g, cpk, sm, si2, mc)
            pbar += p
            hbar += binary_entropy(p)
        pbar /= m
        out_phit[k] = pbar
        out_info[k] = binary_entropy(pbar) - hbar / m


def urban_information(model: UrbanModel, cx: np.ndarray, cy: np.ndarray, pz: float, plan: tuple[np.ndarray, ...],
                      mc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expected information [bits] and predicted hit probability of one reading at each candidate
    point (cx, cy) [m NED], height pz [m], over the planning set ``plan`` (n, e, h, q, cos delta,
    sin delta) with the urban likelihood of ``model`` (model constants ``mc``)."""
    info = np.empty(len(cx))
    phit = np.empty(len(cx))
    paths, lens = model.paths(cx, cy)
    gp, _, _, solid = model.plane.args()
    pn, pe, h, q, cd, sd = plan
    expected_information_urban(paths, lens, pz, pn, pe, h, q, cd, sd, mc, gp, solid, model.mix_rate, info, phit)
    return info, phit
