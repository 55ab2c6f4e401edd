"""Detection model of the source-term estimation (STE) posterior: P(hit | source, sensor, wind).

What a reading tells about a source hypothesis. A hypothesis is a source at horizontal position
(n, e) [m, NED], height ``h`` [m above the ground], release rate ``q`` [g/s] and a plume
direction offset ``delta`` [rad] from the measured mean wind direction. At a sensor point the
mean (time-averaged) concentration is the Gaussian plume with ground reflection and the Briggs
open-country spreads of the assumed Pasquill-Gifford class (Briggs 1973; the formula of
``sitl.world.plume.gaussian_plume_concentration``), with a source size ``r0`` in quadrature::

    C = 1000 q / (2 pi u sy sz) exp(-y^2 / 2 sy^2) [exp(-(z - h)^2 / 2 sz^2) + exp(-(z + h)^2 / 2 sz^2)]

(x downwind, y crosswind of the hypothesis' source, z the sensor height; mg/m^3 for q in g/s).
A real plume is intermittent and meanders: a sensor inside the mean plume reads above the
detection limit only part of the time, the less the further downwind. The model (per source
hypothesis, at x m downwind, y crosswind, sensor height z):

- the mean plume is an *instantaneous* plume (a share ``1 - MF`` of the class's crosswind
  variance, plus ``r0^2``) that meanders crosswind: its centreline is offset by xi sigma_m, with
  sigma_m^2 = MF sigma_y^2 + (theta_m x)^2 (a share ``MF`` of the variance plus a direction sigma
  ``theta_m``), xi a standard normal random effect shared by the readings of a window and
  marginalized over Gauss-Hermite nodes (``meander_nodes``);
- inside the instantaneous plume the sensor is in a puff with probability g(x) = 1 / (1 + x / L)
  (intermittency length ``L``; a two-state Markov chain from one reading to the next, persistence
  ``rho``, in ``accumulate``), and in a puff the concentration is exponentially distributed with
  mean c / g, so P(hit | in) = exp(-g c_thr / c) with ``c_thr`` the detection limit;
- ``eps`` is the floor both ways: a hit where the model says "impossible" (or a miss where it
  says "certain") costs a bounded amount, so a model error cannot veto a hypothesis outright;
- upwind of a hypothesis (x < 0) nothing is released, but a reading's place is uncertain by
  about a metre: the probability at x = 0+ falls off upwind with a Gaussian of ``sigma_up``.

``L``, ``MF``, ``theta_m`` and ``r0`` are fitted to the simulator's puff plume (moderate
turbulence, class D, 5 m/s, sensors at 2/3/5 m height from 0.5 to 90 m downwind, development
seeds; ``benchmarks/infotaxis_detection_model.py`` prints the fit and the table): L = 35 m,
MF = 0.35, theta_m = 6.2 deg, r0 = 0.44 m. The defaults are a model of moderate turbulence; in
high turbulence the plume is more intermittent and wanders further, and a mismatch is measured
(``ste_adapt``), not assumed away. The release rate is a free parameter of the posterior, so
``q`` is the *effective* rate of this model (0.04 g/s in the fit for the 1 g/s simulated
source: in a puff the model's concentration is exponentially distributed, and the fit matches the
share of bins with a hit, not the concentration): a less sensitive sensor, or a weaker source, only moves ``q``.

Hot kernels (numba): the posterior update over all particles and the expected information of a
binary reading at candidate points (infotaxis, Vergassola et al. 2007: the expected entropy
drop of one reading = the mutual information between the reading and the source,
I = H(p_bar) - sum_i w_i H(p_i), exact for a binary reading over a weighted particle set).

Units SI (m, s, m/s, rad), NED horizontal positions (north, east); heights above the ground.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Briggs (1973) open-country coefficients, sigma = a x (1 + b x)^p for x in m: (a, b, p) per
#: Pasquill-Gifford class, crosswind (y) and vertical (z). The same table as the simulator's
#: plume (a test checks it against ``sitl.world.plume.briggs_sigmas``); kept here because a
#: strategy runs on a vehicle without the simulator.
BRIGGS_Y: dict[str, tuple[float, float, float]] = {
    "A": (0.22, 1e-4, -0.5), "B": (0.16, 1e-4, -0.5), "C": (0.11, 1e-4, -0.5),
    "D": (0.08, 1e-4, -0.5), "E": (0.06, 1e-4, -0.5), "F": (0.04, 1e-4, -0.5),
}  # fmt: skip
BRIGGS_Z: dict[str, tuple[float, float, float]] = {
    "A": (0.20, 0.0, 0.0), "B": (0.12, 0.0, 0.0), "C": (0.08, 2e-4, -0.5),
    "D": (0.06, 1.5e-3, -0.5), "E": (0.03, 3e-4, -1.0), "F": (0.016, 3e-4, -1.0),
}  # fmt: skip
STABILITY_CLASSES: tuple[str, ...] = tuple(BRIGGS_Y)

# Layout of the model-constant vector the kernels take (one float64 array, numba-friendly).
_AY, _BY, _PY, _AZ, _BZ, _PZ, _R02, _L, _CTHR, _EPS, _SUP2, _MF, _MTH2 = range(13)
N_CONSTS = 13
#: Index of the meander's squared direction sigma [rad^2] in the constant vector.
MTH2 = _MTH2
#: Index of the floor ``eps`` of P(hit) and P(miss) in the constant vector.
EPS = _EPS
#: Indices of the crosswind Briggs coefficient a_y, the source size r0^2 [m^2] and sigma_up^2 [m^2].
AY, R02, SUP2 = _AY, _R02, _SUP2


def model_constants(stability: str, source_radius_m: float, intermittency_length_m: float,
                    detection_limit_mg_m3: float, eps: float, sigma_up_m: float, meander_fraction: float,
                    meander_rad: float) -> np.ndarray:
    """The constant vector of the kernels (see module docstring for every symbol)."""
    if stability not in BRIGGS_Y:
        raise ValueError(f"stability {stability!r}: one of {', '.join(STABILITY_CLASSES)}")
    ay, by, py = BRIGGS_Y[stability]
    az, bz, pz = BRIGGS_Z[stability]
    return np.array([ay, by, py, az, bz, pz, source_radius_m**2, intermittency_length_m, detection_limit_mg_m3,
                     eps, sigma_up_m**2, meander_fraction, meander_rad**2], dtype=np.float64)


def set_meander(mc: np.ndarray, meander_rad: float) -> None:
    """Set the meander's direction sigma [rad] of the constant vector ``mc`` in place."""
    mc[_MTH2] = meander_rad**2


def meander_of(mc: np.ndarray) -> float:
    """The meander's direction sigma [rad] of the constant vector ``mc``."""
    return float(np.sqrt(mc[_MTH2]))


def meander_nodes(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Hermite nodes (standard normal) and log weights of the meander random effect."""
    x, w = np.polynomial.hermite_e.hermegauss(n)
    return x.astype(np.float64), np.log(w / w.sum())


@njit(cache=True, inline="always")
def _spread(a: float, b: float, p: float, x: float) -> float:
    """Briggs sigma a x (1 + b x)^p [m] for p in {0, -0.5, -1}."""
    if p == 0.0:
        return a * x
    if p == -0.5:
        return a * x / math.sqrt(1.0 + b * x)
    return a * x / (1.0 + b * x)


@njit(cache=True)
def plume_frame(x: float, z: float, h: float, q: float, u: float, mc: np.ndarray
                ) -> tuple[float, float, float, float]:
    """At ``x`` m downwind of a source of height ``h`` [m], rate ``q`` [g/s], in wind ``u`` [m/s],
    sensor height ``z`` [m]: (g, c_peak, sigma_meander, sigma_inst^2): intermittency (times
    the upwind fall-off), the peak [mg/m^3] of the instantaneous plume there, the meander
    sigma [m] and the instantaneous plume's crosswind variance [m^2].

    Upwind of the source (x < 0) nothing is released, but a reading's position is uncertain
    (navigation noise, the sensor's lag, the length of a bin): the detection probability just
    downwind of the source is spread upwind with a Gaussian fall-off of sigma_up (a factor on
    the probability, not on the concentration, which near a source is a thousand times the
    detection limit)."""
    up = 1.0
    if x < 0.05:
        up = math.exp(-0.5 * (x - 0.05) ** 2 / mc[_SUP2])
        x = 0.05
    by = _spread(mc[_AY], mc[_BY], mc[_PY], x)
    bz = _spread(mc[_AZ], mc[_BZ], mc[_PZ], x)
    si2 = (1.0 - mc[_MF]) * by * by + mc[_R02]
    sz2 = bz * bz + mc[_R02]
    sm = math.sqrt(mc[_MF] * by * by + mc[_MTH2] * x * x)
    vert = math.exp(-0.5 * (z - h) ** 2 / sz2) + math.exp(-0.5 * (z + h) ** 2 / sz2)
    cpk = 1000.0 * q / (2.0 * math.pi * u * math.sqrt(si2 * sz2)) * vert
    return up / (1.0 + x / mc[_L]), cpk, sm, si2


@njit(cache=True, inline="always")
def _pd(c: float, g: float, mc: np.ndarray) -> float:
    """P(hit) for instantaneous-plume concentration ``c`` [mg/m^3] and intermittency ``g``
    (exponentially distributed concentration of mean c / g while in the plume)."""
    eps = mc[_EPS]
    if c <= 0.0 or g <= 0.0:
        return eps
    return eps + (1.0 - 2.0 * eps) * g * math.exp(-g * mc[_CTHR] / c)


@njit(cache=True)
def detection_prob(x: float, y: float, z: float, h: float, q: float, u: float, mc: np.ndarray) -> float:
    """P(hit) averaged over the meander, approximated by the mean plume (the instantaneous plume
    widened by the meander, its peak lowered to keep the mass): for moves and display."""
    g, cpk, sm, si2 = plume_frame(x, z, h, q, u, mc)
    return mean_plume_prob(y, g, cpk, sm, si2, mc)


@njit(cache=True, inline="always")
def mean_plume_prob(y: float, g: float, cpk: float, sm: float, si2: float, mc: np.ndarray) -> float:
    """P(hit) ``y`` m crosswind in the mean plume of ``plume_frame``'s (g, c_peak, sigma_meander,
    sigma_inst^2): the instantaneous plume widened by the meander, its peak lowered to keep the mass."""
    s2 = si2 + sm * sm
    return _pd(cpk * math.sqrt(si2 / s2) * math.exp(-0.5 * y * y / s2), g, mc)


@njit(cache=True)
def detection_prob_node(x: float, y: float, z: float, h: float, q: float, u: float, xi: float, mc: np.ndarray
                        ) -> float:
    """P(hit) with the plume meandered ``xi`` meander sigmas crosswind."""
    g, cpk, sm, si2 = plume_frame(x, z, h, q, u, mc)
    d = y - xi * sm
    return _pd(cpk * math.exp(-0.5 * d * d / si2), g, mc)


@njit(cache=True, inline="always")
def _local(px: float, py: float, n: float, e: float, cd: float, sd: float, cphi: float, sphi: float
           ) -> tuple[float, float]:
    """(downwind, crosswind) coordinates [m] of point (px, py) from a source at (n, e) whose plume
    goes along the mean downwind heading (cos, sin = cphi, sphi) turned by delta (cos, sin = cd, sd)."""
    dn = cphi * cd - sphi * sd
    de = sphi * cd + cphi * sd
    dx = px - n
    dy = py - e
    return dx * dn + dy * de, -dx * de + dy * dn


@njit(cache=True)
def accumulate(acc: np.ndarray, alpha: np.ndarray, n: np.ndarray, e: np.ndarray, h: np.ndarray, q: np.ndarray,
               cd: np.ndarray, sd: np.ndarray, px: float, py: float, pz: float, cphi: float, sphi: float, u: float,
               hit: bool, kappa: float, rho: float, nodes: np.ndarray, mc: np.ndarray) -> None:
    """One reading (hit or miss at (px, py) [m NED], height pz [m]) for every particle i and
    meander node j: ``acc[i, j]`` += kappa log P(reading | past readings of the window), and
    ``alpha[i, j]``, the probability that the sensor is inside the intermittent plume (a
    two-state Markov chain: the state persists from one reading to the next with probability
    ``rho``, else is redrawn with P(in) = g; a negative alpha means "no reading yet": g), is
    updated to its posterior. Inside, P(hit) = exp(-g c_thr / c); outside, eps."""
    for i in range(acc.shape[0]):
        x, y = _local(px, py, n[i], e[i], cd[i], sd[i], cphi, sphi)
        g, cpk, sm, si2 = plume_frame(x, pz, h[i], q[i], u, mc)
        weigh_particle(acc, alpha, i, y, g, cpk, sm, si2, hit, kappa, rho, nodes, mc)


@njit(cache=True, inline="always")
def weigh_particle(acc: np.ndarray, alpha: np.ndarray, i: int, y: float, g: float, cpk: float, sm: float,
                   si2: float, hit: bool, kappa: float, rho: float, nodes: np.ndarray, mc: np.ndarray) -> None:
    """One reading for particle ``i``, ``y`` m crosswind of its plume whose frame at the sensor is
    ``plume_frame``'s (g, c_peak, sigma_meander, sigma_inst^2): the body of :func:`accumulate`
    (shared with the urban likelihood, ``mission.strategies.ste_urban``)."""
    eps = mc[_EPS]
    for j in range(nodes.shape[0]):
        d = y - nodes[j] * sm
        c = cpk * math.exp(-0.5 * d * d / si2)
        e_in = eps
        if c > 0.0 and g > 0.0:
            e_in = eps + (1.0 - 2.0 * eps) * math.exp(-g * mc[_CTHR] / c)
        a0 = alpha[i, j]
        p_in = g if a0 < 0.0 else rho * a0 + (1.0 - rho) * g
        if hit:
            lik = p_in * e_in + (1.0 - p_in) * eps
            post = p_in * e_in / lik
        else:
            lik = p_in * (1.0 - e_in) + (1.0 - p_in) * (1.0 - eps)
            post = p_in * (1.0 - e_in) / lik
        alpha[i, j] = post
        acc[i, j] += kappa * math.log(lik)


@njit(cache=True)
def fold(logw: np.ndarray, acc: np.ndarray, log_wts: np.ndarray, out: np.ndarray) -> float:
    """out[i] = logw[i] + log sum_j exp(log_wts[j] + acc[i, j]): the log weight with the current
    meander window marginalized; returns max(out)."""
    best = -np.inf
    for i in range(acc.shape[0]):
        m = -np.inf
        for j in range(acc.shape[1]):
            v = log_wts[j] + acc[i, j]
            if v > m:
                m = v
        s = 0.0
        for j in range(acc.shape[1]):
            s += math.exp(log_wts[j] + acc[i, j] - m)
        out[i] = logw[i] + m + math.log(s)
        if out[i] > best:
            best = out[i]
    return best


@njit(cache=True, inline="always")
def binary_entropy(p: float) -> float:
    """Entropy of a binary variable with P(1) = p, in bits."""
    if p <= 0.0 or p >= 1.0:
        return 0.0
    return -(p * math.log2(p) + (1.0 - p) * math.log2(1.0 - p))


@njit(cache=True)
def expected_information(cx: np.ndarray, cy: np.ndarray, pz: float, n: np.ndarray, e: np.ndarray, h: np.ndarray,
                         q: np.ndarray, cd: np.ndarray, sd: np.ndarray, cphi: float, sphi: float, u: float,
                         mc: np.ndarray, out_info: np.ndarray, out_phit: np.ndarray) -> None:
    """Mutual information [bits] between a reading at each candidate point (cx[k], cy[k]) [m NED],
    height pz, and the source, over equally weighted particles: out_info[k]; the predicted hit
    probability: out_phit[k]."""
    m = n.shape[0]
    for k in range(cx.shape[0]):
        pbar = 0.0
        hbar = 0.0
        for i in range(m):
            x, y = _local(cx[k], cy[k], n[i], e[i], cd[i], sd[i], cphi, sphi)
            p = detection_prob(x, y, pz, h[i], q[i], u, mc)
            pbar += p
            hbar += binary_entropy(p)
        pbar /= m
        out_phit[k] = pbar
        out_info[k] = binary_entropy(pbar) - hbar / m


def detection_grid(xs: np.ndarray, ys: np.ndarray, z: float, h: float, q: float, u: float, mc: np.ndarray
                   ) -> np.ndarray:
    """P(hit) on a grid of downwind ``xs`` x crosswind ``ys`` [m] (for benchmarks and tests)."""
    out = np.empty((len(xs), len(ys)))
    for i, x in enumerate(xs):
        for j, y in enumerate(ys):
            out[i, j] = detection_prob(float(x), float(y), z, h, q, u, mc)
    return out
