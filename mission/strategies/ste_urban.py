"""Urban likelihood of the STE posterior: backward (adjoint) trajectories through the city's wind.

Among buildings a plume does not go straight downwind: the streets turn it, a lee or a courtyard
holds it in recirculating air. The open-field model (``mission.strategies.ste_model``) then puts
a source where a straight line upwind from the hits leads -- in a building's lee. Here the
source-receptor relationship is computed in the mean wind the vehicle is actually in (the urban
diagnostic field of the known buildings with the estimated inflow,
``mission.strategies.ste_urban_field``), by the adjoint (backward) route of Keats, Yee & Lien
(2007): for a reading, the region of sources that could have reached the sensor is found by
transport backward in time from the sensor through the *reversed* mean flow, with a turbulent
spread that grows with travel. Our form is Lagrangian and cheap (a centreline instead of Keats'
adjoint advection-diffusion solve):

- **Backward path** (:func:`backward_paths`): from the reading's position, steps of ``step`` m
  along the reversed mean wind -V/|V| of the horizontal slice at the flight altitude, up to
  ``length`` m; per point (north, east) [m], travel distance s [m], travel time tau [s] (s over
  the local speed, floored at ``SPEED_FLOOR`` x the inflow speed) and the distance travelled in
  "mixing" air. Where the mean flow gives no upwind direction -- slower than ``stall`` x the
  inflow speed (the backward paths converge on a cavity's stagnation line and cannot enter it),
  or reversed so that following it backward would lead *downwind* (a lee cavity, a courtyard's
  recirculation) -- the path goes straight along the inflow's upwind direction and that distance
  counts as mixing: material is mixed through the recirculating volume (the cavity is a
  well-mixed box in the building-wake models Keats et al. build on). A step into a building
  slides along it (the next free direction within +-90 deg that does not turn back), round the
  building: material reaches a lee from around it. Only a closed corner ends a path, and nothing
  lies beyond its end. Tried and dropped on development seeds 100-109 of paper-s4 (8 of 10
  within 3 m with the rules above): following the reversed flow inside a recirculation together
  with ending a mixing path at the first wall (one run with both: 4 of 10, a declaration at a
  wall 93 m off; in paper-s4-wind90 declarations in block-5's lee, 56 m off).
- **Footprint** (:func:`accumulate_urban`; the move choice's ``ste_urban_plan``): a source
  hypothesis at (n, e) is placed in the path's frame: x = the travel distance to its closest
  point on the path (beyond the ends the path is extended straight), y = its signed distance
  from the path; the direction offset delta of the particle rotates (x, y) as in the open field
  (small-angle). The detection model is then the open field's (Briggs spreads of x, intermittency,
  meander; ``ste_model.plume_frame``) with the wind speed s / tau (the mean speed along the path:
  slower air dilutes less; floored at ``PLUME_SPEED_FLOOR`` x the inflow speed) and an extra
  crosswind variance (``mix_rate`` x mixing distance)^2.
  Far from buildings the reversed field is uniform and the path a straight upwind line: the model
  reduces to the open-field plume (a test checks it).
- A source hypothesis inside a building (at the flight altitude) is penalized by
  ``SOLID_LOG_PENALTY`` per reading (tempered): the buildings are known, a source is outside.

Anchors: Keats, Yee & Lien, "Bayesian inference for source determination with applications to a
complex urban environment", Atmospheric Environment 41 (2007) -- the adjoint source-receptor
relationship in an urban flow and a Bayesian posterior over the source; Ristic, Gunatilaka &
Gailis, "Localisation of a source of hazardous substance dispersion using binary measurements",
Atmospheric Environment 142 (2016), and Ristic et al. 2016 on UAV source-term estimation -- the
binary-reading likelihood and the particle posterior this model plugs into; the PMFS algorithm of
the MAPIR gas-source-localization suite (Ojeda et al.) -- source hypotheses scored by how the
local wind could have carried gas from them to the sensor.

Units SI; frame local NED (north, east) [m]; heights above the ground; wind = air-mass velocity.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mission.strategies.ste_model import (
    AY,
    MTH2,
    R02,
    SUP2,
    plume_frame,
    weigh_particle,
)
from mission.strategies.ste_urban_field import UrbanPlane

#: Columns of a path point: north, east [m], travel distance s [m], travel time tau [s], mixing distance [m].
P_N, P_E, P_S, P_T, P_MIX = range(5)
PATH_COLS = 5
#: The closest path point is sought among every COARSE-th point first, then about the best of them.
COARSE = 4
#: Sources further off a candidate's path than this many (bounding) plume sigmas count as eps.
FAR_SIGMAS = 6.0
#: Travel time uses the local speed floored at this share of the inflow speed.
SPEED_FLOOR = 0.2
#: The plume's wind speed s / tau is floored at this share of the inflow speed (a plume through
#: stalled air is diluted by its turbulence, not only by the mean wind).
PLUME_SPEED_FLOOR = 0.5
#: Tempered log-likelihood added per reading to a source hypothesis inside a building.
SOLID_LOG_PENALTY = math.log(0.2)
#: Slide directions tried when a step meets a building [rad].
_SLIDES = (0.7853981633974483, -0.7853981633974483, 1.5707963267948966, -1.5707963267948966)


@njit(cache=True, inline="always")
def _velocity(gp: np.ndarray, un: np.ndarray, ue: np.ndarray, n: float, e: float) -> tuple[float, float]:
    """Bilinear mean wind (north, east) [m/s] at (n, e); the inflow outside the slice."""
    fi = (n - gp[0]) / gp[2]
    fj = (e - gp[1]) / gp[2]
    nx, ny = int(gp[3]), int(gp[4])
    if fi < 0.0 or fj < 0.0 or fi > nx - 1 or fj > ny - 1:
        return -gp[5] * gp[7], -gp[6] * gp[7]
    i = min(int(fi), nx - 2)
    j = min(int(fj), ny - 2)
    a = fi - i
    b = fj - j
    vn = (1 - a) * ((1 - b) * un[i, j] + b * un[i, j + 1]) + a * ((1 - b) * un[i + 1, j] + b * un[i + 1, j + 1])
    ve = (1 - a) * ((1 - b) * ue[i, j] + b * ue[i, j + 1]) + a * ((1 - b) * ue[i + 1, j] + b * ue[i + 1, j + 1])
    return vn, ve


@njit(cache=True)
def flow_at(gp: np.ndarray, un: np.ndarray, ue: np.ndarray, n: float, e: float) -> tuple[float, float]:
    """The slice's mean wind (north, east) [m/s] at (n, e) [m] (for the strategy's checks)."""
    return _velocity(gp, un, ue, n, e)


@njit(cache=True, inline="always")
def is_solid(gp: np.ndarray, solid: np.ndarray, n: float, e: float) -> bool:
    """Whether (n, e) [m] is inside a building at the flight altitude (nearest slice corner)."""
    i = int(math.floor((n - gp[0]) / gp[2] + 0.5))
    j = int(math.floor((e - gp[1]) / gp[2] + 0.5))
    if i < 0 or j < 0 or i >= solid.shape[0] or j >= solid.shape[1]:
        return False
    return solid[i, j] > 0


@njit(cache=True)
def _one_path(px: float, py: float, gp: np.ndarray, un: np.ndarray, ue: np.ndarray, solid: np.ndarray,
              step: float, stall: float, out: np.ndarray) -> int:
    """The backward path from (px, py) into ``out`` (kmax, PATH_COLS); returns its point count."""
    upn, upe, u0 = gp[5], gp[6], gp[7]
    n, e, s, tau, mix = px, py, 0.0, 0.0, 0.0
    out[0, P_N], out[0, P_E], out[0, P_S], out[0, P_T], out[0, P_MIX] = n, e, 0.0, 0.0, 0.0
    k = 1
    pn, pe = upn, upe  # the previous step's direction
    while k < out.shape[0]:
        vn, ve = _velocity(gp, un, ue, n, e)
        sp = math.sqrt(vn * vn + ve * ve)
        dn, de, mixing = upn, upe, True
        if sp > stall * u0 and -(vn * upn + ve * upe) > 0.0:
            dn, de, mixing = -vn / sp, -ve / sp, False
        if is_solid(gp, solid, n + step * dn, e + step * de):
            free = False
            for ang in _SLIDES:
                c, sn = math.cos(ang), math.sin(ang)
                tn, te = dn * c - de * sn, dn * sn + de * c
                if tn * pn + te * pe > -0.1 and not is_solid(gp, solid, n + step * tn, e + step * te):
                    dn, de, free = tn, te, True
                    break
            if not free:  # a closed corner: no way on without turning back
                break
        pn, pe = dn, de
        n += step * dn
        e += step * de
        s += step
        tau += step / max(sp, SPEED_FLOOR * u0)
        if mixing:
            mix += step
        out[k, P_N], out[k, P_E], out[k, P_S], out[k, P_T], out[k, P_MIX] = n, e, s, tau, mix
        k += 1
    return k


@njit(cache=True)
def backward_paths(px: np.ndarray, py: np.ndarray, gp: np.ndarray, un: np.ndarray, ue: np.ndarray,
                   solid: np.ndarray, step: float, stall: float, out: np.ndarray, lens: np.ndarray) -> None:
    """Backward paths from every point (px[k], py[k]) [m NED] into ``out[k]`` (kmax points of
    PATH_COLS, ``step`` m apart; the path length is (kmax - 1) step), their point counts into
    ``lens[k]`` (module docstring)."""
    for k in range(px.shape[0]):
        lens[k] = _one_path(px[k], py[k], gp, un, ue, solid, step, stall, out[k])


@njit(cache=True, inline="always")
def _on_segment(path: np.ndarray, k: int, sn: float, se: float, lo_open: bool, hi_open: bool
                ) -> tuple[float, float, float]:
    """(squared distance, t, side) of (sn, se) to segment k of ``path`` (t in [0, 1], below 0 when
    ``lo_open``, above 1 when ``hi_open``; the distance is to the clamped point, ``side``'s sign the
    side of the segment: the signed distance is copysign(sqrt(squared distance), side), taken only
    for the segment kept)."""
    an, ae = path[k, P_N], path[k, P_E]
    ln, le = path[k + 1, P_N] - an, path[k + 1, P_E] - ae
    dn, de = sn - an, se - ae
    l2 = ln * ln + le * le
    if l2 <= 0.0:
        return dn * dn + de * de, 0.0, 0.0
    t = (dn * ln + de * le) / l2
    if t < 0.0 and not lo_open:
        t = 0.0
    if t > 1.0 and not hi_open:
        t = 1.0
    rn, re = dn - t * ln, de - t * le
    return rn * rn + re * re, t, ln * de - le * dn


@njit(cache=True, inline="always")
def path_frame(path: np.ndarray, k_len: int, sn: float, se: float, upn: float, upe: float
               ) -> tuple[float, float, float, float]:
    """A source at (sn, se) [m] in the frame of a backward path of ``k_len`` points: (x = travel
    distance to its closest point [m], y = signed distance from the path [m], travel time there
    [s], mixing distance there [m]). The closest path point is found first (coarse to fine: a
    path is smooth on the scale of ``COARSE`` steps), then the closest point on its two segments;
    before the first point, and after the last of a path that was not stopped by a wall (``k_len``
    = its full length), the path is extended straight
    (a one-point path along the upwind direction (upn, upe))."""
    if k_len < 2:
        dn, de = sn - path[0, P_N], se - path[0, P_E]
        return dn * upn + de * upe, dn * upe - de * upn, 0.0, 0.0
    best = np.inf
    kc = 0
    for k in range(0, k_len, COARSE):  # every COARSE-th point, then the points about the best of them
        dn, de = sn - path[k, P_N], se - path[k, P_E]
        d2 = dn * dn + de * de
        if d2 < best:
            best, kc = d2, k
    return frame_about(path, k_len, sn, se, kc, best)


@njit(cache=True)
def coarse_closest(path: np.ndarray, k_len: int, n: np.ndarray, e: np.ndarray, best: np.ndarray,
                   kc: np.ndarray) -> None:
    """For every particle (n[i], e[i]) [m]: the closest of the path points 0, COARSE, 2 COARSE, ...
    below ``k_len`` (the first of equals) into ``kc[i]``, its squared distance [m^2] into ``best[i]``
    (:func:`path_frame`'s coarse stage for many sources; points outer, particles inner: the compiler
    vectorizes it)."""
    best[:] = np.inf
    kc[:] = 0
    for k in range(0, k_len, COARSE):
        pn, pe = path[k, P_N], path[k, P_E]
        for i in range(n.shape[0]):
            dn = n[i] - pn
            de = e[i] - pe
            d2 = dn * dn + de * de
            if d2 < best[i]:
                best[i] = d2
                kc[i] = k


@njit(cache=True, inline="always")
def frame_about(path: np.ndarray, k_len: int, sn: float, se: float, kc: int, best: float
                ) -> tuple[float, float, float, float]:
    """:func:`path_frame` (``k_len`` >= 2) from its coarse stage's result: ``kc`` the closest of every
    ``COARSE``-th path point to (sn, se) [m] (the first of equals), ``best`` its squared distance [m^2]
    (the move choice finds them for all particles at once, ``ste_urban_plan``)."""
    kb = kc
    for k in range(max(kc - COARSE + 1, 0), min(kc + COARSE, k_len)):
        dn, de = sn - path[k, P_N], se - path[k, P_E]
        d2 = dn * dn + de * de
        if d2 < best:
            best, kb = d2, k
    kk = min(kb, k_len - 2)
    open_end = k_len == path.shape[0]  # a path that ended early met a wall: nothing beyond it
    d2, tt, side = _on_segment(path, kk, sn, se, kk == 0, kk == k_len - 2 and open_end)
    if kb > 0 and kb < k_len - 1:
        d2b, tb, sb = _on_segment(path, kb - 1, sn, se, kb - 1 == 0, False)
        if d2b < d2:
            kk, d2, tt, side = kb - 1, d2b, tb, sb
    yy = math.copysign(math.sqrt(d2), side)
    s0, s1 = path[kk, P_S], path[kk + 1, P_S]
    t0, t1 = path[kk, P_T], path[kk + 1, P_T]
    x = s0 + tt * (s1 - s0)
    tc = min(max(tt, 0.0), 1.0)
    tau = t0 + tt * (t1 - t0) if tt > 1.0 else t0 + tc * (t1 - t0)
    return x, yy, tau, path[kk, P_MIX] + tc * (path[kk + 1, P_MIX] - path[kk, P_MIX])


@njit(cache=True, inline="always")
def plume_in_path_frame(x0: float, y0: float, tau: float, mix: float, cd: float, sd: float, pz: float, h: float,
                        q: float, gp: np.ndarray, mix_rate: float, mc: np.ndarray
                        ) -> tuple[float, float, float, float, float]:
    """(y, g, c_peak, sigma_meander, sigma_inst^2) of a source hypothesis at the sensor from its place
    (x0, y0, tau, mix) in the backward path's frame (:func:`path_frame`; module docstring)."""
    x = x0 * cd + y0 * sd
    y = -x0 * sd + y0 * cd
    u = gp[7] if tau <= 0.0 or x0 <= 0.0 else max(x0 / tau, PLUME_SPEED_FLOOR * gp[7])
    g, cpk, sm, si2 = plume_frame(x, pz, h, q, u, mc)
    if mix > 0.0:
        extra = (mix_rate * mix) ** 2
        cpk *= math.sqrt(si2 / (si2 + extra))
        si2 += extra
    return y, g, cpk, sm, si2


@njit(cache=True, inline="always")
def near_path(x0: float, y0: float, mix: float, cd: float, sd: float, mix_rate: float, mc: np.ndarray) -> bool:
    """False when a source at (x0, y0, mix) in a backward path's frame (:func:`path_frame`) is more
    than ``FAR_SIGMAS`` of an upper bound of the mean plume's crosswind sigma (a_y x, the meander, r0
    and the mixing spread) off the path, or that many sigma_up behind the sensor: its P(hit) is then
    eps to within 1e-7 (for the move choice only)."""
    x = x0 * cd + y0 * sd
    y = -x0 * sd + y0 * cd
    if x < -FAR_SIGMAS * math.sqrt(mc[SUP2]):
        return False
    s2 = (mc[AY] * mc[AY] + mc[MTH2]) * x * x + mc[R02] + (mix_rate * mix) ** 2 + 1.0
    return y * y < FAR_SIGMAS * FAR_SIGMAS * s2


@njit(cache=True)
def accumulate_urban(acc: np.ndarray, alpha: np.ndarray, n: np.ndarray, e: np.ndarray, h: np.ndarray,
                     q: np.ndarray, cd: np.ndarray, sd: np.ndarray, path: np.ndarray, k_len: int, pz: float,
                     hit: bool, kappa: float, rho: float, nodes: np.ndarray, mc: np.ndarray, gp: np.ndarray,
                     solid: np.ndarray, mix_rate: float) -> None:
    """One reading (hit or miss, sensor height pz [m]) whose backward path is ``path[:k_len]``, for
    every particle: ``ste_model.accumulate`` with the urban frame (module docstring)."""
    best = np.empty(acc.shape[0])
    kc = np.zeros(acc.shape[0], dtype=np.int64)
    if k_len >= 2:
        coarse_closest(path, k_len, n, e, best, kc)
    for i in range(acc.shape[0]):
        if is_solid(gp, solid, n[i], e[i]):
            for j in range(acc.shape[1]):
                acc[i, j] += kappa * SOLID_LOG_PENALTY
            continue
        if k_len >= 2:
            x0, y0, tau, mix = frame_about(path, k_len, n[i], e[i], kc[i], best[i])
        else:
            x0, y0, tau, mix = path_frame(path, k_len, n[i], e[i], gp[5], gp[6])
        y, g, cpk, sm, si2 = plume_in_path_frame(x0, y0, tau, mix, cd[i], sd[i], pz, h[i], q[i], gp, mix_rate, mc)
        weigh_particle(acc, alpha, i, y, g, cpk, sm, si2, hit, kappa, rho, nodes, mc)


class UrbanModel:
    """The urban likelihood's settings over one :class:`~mission.strategies.ste_urban_field.UrbanPlane`:
    backward paths of ``length_m`` in steps of ``step_m`` [m], the stall share ``stall`` of the
    inflow speed and the mixing spread ``mix_rate`` [m of sigma per m] (module docstring)."""

    def __init__(self, plane: UrbanPlane, step_m: float = 3.0, length_m: float = 240.0, stall: float = 0.15,
                 mix_rate: float = 0.15) -> None:
        self.plane = plane
        self.step = float(step_m)
        self.kmax = int(round(length_m / step_m)) + 1
        self.stall = float(stall)
        self.mix_rate = float(mix_rate)

    def paths(self, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Backward paths from the points (px, py) [m NED]: (paths (K, kmax, PATH_COLS), lens (K,))."""
        px = np.ascontiguousarray(px, dtype=np.float64)
        py = np.ascontiguousarray(py, dtype=np.float64)
        out = np.zeros((len(px), self.kmax, PATH_COLS))
        lens = np.zeros(len(px), dtype=np.int64)
        gp, un, ue, solid = self.plane.args()
        backward_paths(px, py, gp, un, ue, solid, self.step, self.stall, out, lens)
        return out, lens
