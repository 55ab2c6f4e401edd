"""Chemical plume models: time-averaged Gaussian plume and instantaneous puff (filament) plume.

Conventions
-----------
- SI units throughout, except the two chemical quantities below.
- World frame NED: x north, y east, z down; the ground is the plane z = 0 and
  altitude = -z. All positions are NED metres.
- Wind is the AIR-MASS VELOCITY in NED (m/s): a 10 m/s wind from the north is
  [-10, 0, 0]. The plume is carried *with* that velocity.
- Release rate in g/s; puff masses in g; concentration in mg/m^3.
- Stability: Pasquill-Gifford classes "A" (very unstable) ... "F" (moderately stable).

Models
------
``gaussian_plume_concentration`` / ``GaussianPlume``
    Steady Gaussian plume with ground reflection (image source) and the Briggs
    open-country dispersion coefficients sigma_y(x), sigma_z(x). The formulas are
    tabulated for 100 m < x < 10 km; we extrapolate them to shorter range (they are
    linear in x there, which is what short-range Taylor dispersion gives). A source
    size ``source_radius_m`` is added in quadrature (virtual source) so the field is
    finite at the source. This is the reference for the puff model and a cheap
    likelihood model.

``PuffPlume``
    Instantaneous plume in the manner of Farrell et al. (2002), "Filament-based
    atmospheric dispersion model to achieve short time-scale structure of odor
    plumes" (the model implemented by pompy). Puffs are released from every active
    source at ``puff_rate_hz``; each carries ``rate_g_s / puff_rate_hz`` grams. A puff
    centre moves with

    - the wind the vehicle feels: ``wind.velocity(t, puff_positions)`` (mean, schedule,
      Kaimal turbulence of the wind model),
    - a large-scale *meander*: a smooth random velocity field (sum of random Fourier
      modes, frozen in a frame advected with the mean wind and slowly evolving in
      time) that makes the plume snake; horizontal and vertical parts (the vertical
      part gives the looping of unstable classes),
    - a small-scale random walk (puff-relative dispersion),

    and its radius grows by diffusion, r^2(t) = r0^2 + gamma * age (Farrell's model).
    Concentration is the sum of isotropic 3-D Gaussian puffs of standard deviation r,
    each with its ground image.

Calibration of the puff model against Pasquill-Gifford / Briggs
---------------------------------------------------------------
For one axis (crosswind y or vertical z) Briggs gives sigma(x) = a x (1 + b x)^p.
With travel time tau = x / u (u = reference mean wind speed at the first source,
floored at ``min_wind_speed_m_s``) the puff model spreads puffs with variance

    sigma^2(x) = MEANDER_FRACTION * a^2 u^2 * S_T(tau)          (correlated meander)
               + a^2 * DIFFUSIVE_LENGTH_M * u * tau             (random walk + puff growth)
               + r0^2                                           (source size, also in the
                                                                 Gaussian reference)

where S_T(tau) = 2 T^2 (tau/T - 1 + exp(-tau/T)) is Taylor's dispersion for velocity
fluctuations with unit variance and an exponential Lagrangian correlation time T.
T is matched to the first-order bend of the Briggs curve (T = 1/(3 b u) for
p = -1/2, T = 1/(6 b u) for p = -1, frozen when b = 0). With MEANDER_FRACTION = 0.85
and DIFFUSIVE_LENGTH_M = 3 m the design sigma is within +-8 % of Briggs for every class
and both axes over 10 m < x < 300 m, i.e. the meander velocity standard deviation is
sqrt(0.85) a u and the small-scale variance rate is 3 a^2 u m^2/s per axis. The puff
radius takes half of the smaller (of y, z) small-scale budget, the centre random walk
the rest, so the instantaneous plume (puff + random walk) is several times narrower
than the time-averaged one: patchy, meandering, intermittent. Because a, b differ by
class, class A spreads fastest (looping) and F slowest (fanning).

The meander only decorrelates through its slow temporal evolution and through
puffs drifting across the frozen field, and the field has a finite number of modes,
so the realised spread is close to, not exactly, the design; tests compare the
long-time average with the Gaussian plume within a stated tolerance.

Turbulence in the wind model (Kaimal) moves puffs too. ``sitl.world.wind`` samples it
Taylor-frozen, so a puff riding with the mean wind keeps the same turbulent velocity
for its whole life: it acts like meander with an infinite correlation time. By default
(``subtract_wind_turbulence``) its crosswind / vertical variance is removed from the
meander budget, so the total spread stays that of the stability class; when the wind
turbulence alone exceeds the class budget the plume is wider than the class.

All randomness comes from ``np.random.SeedSequence(seed)``: same seed, same field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numba import njit

STABILITY_CLASSES: tuple[str, ...] = ("A", "B", "C", "D", "E", "F")
PLUME_MODELS: tuple[str, ...] = ("puff", "gaussian")

# Briggs (1973) open-country coefficients: sigma = a * x * (1 + b * x) ** p, x in m.
_BRIGGS_Y: dict[str, tuple[float, float, float]] = {
    "A": (0.22, 1e-4, -0.5),
    "B": (0.16, 1e-4, -0.5),
    "C": (0.11, 1e-4, -0.5),
    "D": (0.08, 1e-4, -0.5),
    "E": (0.06, 1e-4, -0.5),
    "F": (0.04, 1e-4, -0.5),
}
_BRIGGS_Z: dict[str, tuple[float, float, float]] = {
    "A": (0.20, 0.0, 0.0),
    "B": (0.12, 0.0, 0.0),
    "C": (0.08, 2e-4, -0.5),
    "D": (0.06, 1.5e-3, -0.5),
    "E": (0.03, 3e-4, -1.0),
    "F": (0.016, 3e-4, -1.0),
}

#: Share of the Briggs variance carried by the correlated meander (see module docstring).
MEANDER_FRACTION: float = 0.85
#: Length scale of the small-scale (diffusive) variance budget a^2 * L * u [m].
DIFFUSIVE_LENGTH_M: float = 3.0
#: Share of the tighter axis' small-scale budget given to puff growth (rest: random walk).
PUFF_GROWTH_SHARE: float = 0.5
#: Number of Fourier modes of the horizontal / vertical meander field.
N_MEANDER_MODES_H: int = 12
N_MEANDER_MODES_V: int = 8
#: Range of meander wavelengths [m]; log-stratified between these bounds.
MEANDER_WAVELENGTH_RANGE_M: tuple[float, float] = (40.0, 400.0)
#: Interval [s] at which each puff re-samples the meander field.
MEANDER_REFRESH_S: float = 1.0

_G_TO_MG = 1000.0
_TWO_PI_POW_1_5 = (2.0 * math.pi) ** 1.5


class WindLike(Protocol):
    """What the plume needs from a wind model (e.g. ``sitl.world.wind.WindField``)."""

    def mean(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Steady air-mass velocity NED [m/s] at ``pos_ned`` (3,), no turbulence."""
        ...

    def velocity(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Air-mass velocity NED [m/s] with turbulence; (N,3) -> (N,3)."""
        ...


@dataclass(frozen=True)
class Source:
    """A point release.

    position_ned: release point, NED [m] (altitude = -z, must be >= 0).
    rate_g_s: release rate [g/s].
    start_s / stop_s: the source emits for start_s <= t < stop_s [s].
    """

    position_ned: tuple[float, float, float]
    rate_g_s: float
    start_s: float = 0.0
    stop_s: float = math.inf

    def active(self, t: float) -> bool:
        """True while the source emits at time ``t`` [s]."""
        return self.start_s <= t < self.stop_s


@dataclass(frozen=True)
class PlumeConfig:
    """Plume configuration.

    sources: the releases (at least one).
    stability: Pasquill-Gifford class, one of STABILITY_CLASSES.
    model: "puff" (instantaneous, Farrell) or "gaussian" (time-averaged).
    puff_rate_hz: puffs released per second per source.
    max_puffs: cap on live puffs; the oldest are removed (mass accounted).
    update_rate_hz: the puff model integrates with steps no longer than 1/update_rate_hz;
        the simulator should call ``step`` at this rate.
    domain_min_ned / domain_max_ned: optional box [m, NED]; puffs leaving it are removed.
        Either both or neither.
    source_radius_m: initial puff standard deviation r0 [m] (also the virtual source
        size of the Gaussian plume).
    min_wind_speed_m_s: floor on the wind speed used for dilution and dispersion
        scaling, so calm air does not give infinite concentration.
    subtract_wind_turbulence: take the variance of the wind model's Taylor-frozen
        turbulence out of the meander budget so the total spread stays that of the
        stability class (puff model only).
    """

    sources: tuple[Source, ...]
    stability: str = "D"
    model: str = "puff"
    puff_rate_hz: float = 10.0
    max_puffs: int = 1000
    update_rate_hz: float = 10.0
    domain_min_ned: tuple[float, float, float] | None = None
    domain_max_ned: tuple[float, float, float] | None = None
    source_radius_m: float = 0.3
    min_wind_speed_m_s: float = 0.5
    subtract_wind_turbulence: bool = True

    def validate(self) -> list[str]:
        """Return a list of human-readable errors (empty when valid)."""
        errors: list[str] = []
        if len(self.sources) == 0:
            errors.append("sources: at least one Source is required")
        for i, s in enumerate(self.sources):
            pos = np.asarray(s.position_ned, dtype=float)
            if pos.shape != (3,) or not np.all(np.isfinite(pos)):
                errors.append(f"sources[{i}].position_ned: 3 finite NED coordinates [m]")
            elif pos[2] > 0.0:
                errors.append(f"sources[{i}].position_ned: z must be <= 0 (above ground, NED)")
            if not (math.isfinite(s.rate_g_s) and s.rate_g_s >= 0.0):
                errors.append(f"sources[{i}].rate_g_s: finite and >= 0 [g/s]")
            if not (math.isfinite(s.start_s) and s.stop_s > s.start_s):
                errors.append(f"sources[{i}].start_s/stop_s: finite start_s < stop_s [s]")
        if self.stability not in STABILITY_CLASSES:
            errors.append(f"stability: one of {', '.join(STABILITY_CLASSES)}")
        if self.model not in PLUME_MODELS:
            errors.append(f"model: one of {', '.join(PLUME_MODELS)}")
        if not (math.isfinite(self.puff_rate_hz) and self.puff_rate_hz > 0.0):
            errors.append("puff_rate_hz: finite and > 0 [Hz]")
        if self.max_puffs < 1:
            errors.append("max_puffs: integer >= 1")
        if not (math.isfinite(self.update_rate_hz) and self.update_rate_hz > 0.0):
            errors.append("update_rate_hz: finite and > 0 [Hz]")
        if (self.domain_min_ned is None) != (self.domain_max_ned is None):
            errors.append("domain_min_ned/domain_max_ned: give both or neither")
        elif self.domain_min_ned is not None and self.domain_max_ned is not None:
            lo = np.asarray(self.domain_min_ned, dtype=float)
            hi = np.asarray(self.domain_max_ned, dtype=float)
            if lo.shape != (3,) or hi.shape != (3,) or not np.all(lo < hi):
                errors.append("domain_min_ned/domain_max_ned: 3 values each, min < max per axis")
        if not (math.isfinite(self.source_radius_m) and self.source_radius_m > 0.0):
            errors.append("source_radius_m: finite and > 0 [m]")
        if not (math.isfinite(self.min_wind_speed_m_s) and self.min_wind_speed_m_s > 0.0):
            errors.append("min_wind_speed_m_s: finite and > 0 [m/s]")
        return errors


def _check(config: PlumeConfig) -> None:
    errors = config.validate()
    if errors:
        raise ValueError("invalid PlumeConfig: " + "; ".join(errors))


def briggs_sigmas(x_m: np.ndarray, stability: str) -> tuple[np.ndarray, np.ndarray]:
    """Briggs open-country sigma_y, sigma_z [m] at downwind distance ``x_m`` [m] (>= 0)."""
    x = np.maximum(np.asarray(x_m, dtype=float), 0.0)
    ay, by, py = _BRIGGS_Y[stability]
    az, bz, pz = _BRIGGS_Z[stability]
    return ay * x * (1.0 + by * x) ** py, az * x * (1.0 + bz * x) ** pz


def gaussian_plume_concentration(
    points_ned: np.ndarray,
    source_ned: np.ndarray,
    rate_g_s: float,
    wind_ned: np.ndarray,
    stability: str = "D",
    source_radius_m: float = 0.3,
    min_wind_speed_m_s: float = 0.5,
) -> np.ndarray:
    """Steady Gaussian plume concentration [mg/m^3] with ground reflection.

    points_ned: (N,3) or (3,) query points, NED [m].
    source_ned: (3,) release point, NED [m].
    rate_g_s: release rate [g/s].
    wind_ned: mean air-mass velocity NED [m/s]; only its horizontal part is used
        (direction = where the plume goes, speed = dilution, floored at
        ``min_wind_speed_m_s``).
    stability: Pasquill-Gifford class "A".."F".
    source_radius_m: virtual source size added in quadrature to both sigmas [m].

    Returns (N,) or a float for a (3,) input; zero upwind of the source.
    """
    if stability not in STABILITY_CLASSES:
        raise ValueError(f"stability: one of {', '.join(STABILITY_CLASSES)}, got {stability!r}")
    pts = np.asarray(points_ned, dtype=float)
    single = pts.ndim == 1
    pts = np.atleast_2d(pts)
    src = np.asarray(source_ned, dtype=float)
    w = np.asarray(wind_ned, dtype=float)
    speed_h = math.hypot(w[0], w[1])
    u = max(speed_h, min_wind_speed_m_s)
    # With no horizontal wind there is no direction; keep a deterministic one (north).
    e_along = np.array([w[0], w[1]]) / speed_h if speed_h > 1e-9 else np.array([1.0, 0.0])
    e_cross = np.array([-e_along[1], e_along[0]])
    d = pts[:, :2] - src[:2]
    x_down = d @ e_along
    y_cross = d @ e_cross
    sy, sz = briggs_sigmas(x_down, stability)
    r02 = source_radius_m**2
    sy2 = sy**2 + r02
    sz2 = sz**2 + r02
    h = -src[2]
    z = -pts[:, 2]
    conc = (
        rate_g_s
        * _G_TO_MG
        / (2.0 * math.pi * u * np.sqrt(sy2 * sz2))
        * np.exp(-0.5 * y_cross**2 / sy2)
        * (np.exp(-0.5 * (z - h) ** 2 / sz2) + np.exp(-0.5 * (z + h) ** 2 / sz2))
    )
    conc = np.where(x_down > 0.0, conc, 0.0)
    return float(conc[0]) if single else conc


class GaussianPlume:
    """Time-averaged plume with the same ``step``/``concentration`` interface as PuffPlume.

    ``step`` only advances time: it samples the mean wind at each source and tracks
    source timing. A source that switches on at start_s fills the plume from the
    source outward at the wind speed (front at u*(t - start_s)); after stop_s the tail
    leaves the same way, so the on/off timing is visible to a vehicle downwind.
    """

    def __init__(
        self, config: PlumeConfig, wind: WindLike, seed: int | None = None, t0: float = 0.0
    ):
        """config: validated PlumeConfig; wind: wind model; seed: unused (deterministic
        model), accepted for a uniform factory signature; t0: initial time [s]."""
        _check(config)
        self.config = config
        self._wind = wind
        self._src = np.array([s.position_ned for s in config.sources], dtype=float)
        self._t = t0
        self._winds = np.zeros((len(config.sources), 3))
        self._sample_winds()

    @property
    def t(self) -> float:
        """Current plume time [s]."""
        return self._t

    def _sample_winds(self) -> None:
        for i, p in enumerate(self._src):
            self._winds[i] = self._wind.mean(self._t, p)

    def step(self, t: float, dt: float) -> None:
        """Advance from ``t`` to ``t + dt`` [s]."""
        self._t = t + dt
        self._sample_winds()

    def concentration(self, points: np.ndarray) -> np.ndarray | float:
        """Concentration [mg/m^3] at (N,3) NED points -> (N,), or (3,) -> float."""
        pts = np.asarray(points, dtype=float)
        single = pts.ndim == 1
        pts = np.atleast_2d(pts)
        total = np.zeros(len(pts))
        cfg = self.config
        for i, s in enumerate(cfg.sources):
            if self._t < s.start_s:
                continue
            w = self._winds[i]
            c = gaussian_plume_concentration(
                pts,
                self._src[i],
                s.rate_g_s,
                w,
                cfg.stability,
                cfg.source_radius_m,
                cfg.min_wind_speed_m_s,
            )
            # Limit the plume to air released while the source was on.
            speed_h = math.hypot(w[0], w[1])
            u = max(speed_h, cfg.min_wind_speed_m_s)
            e = np.array([w[0], w[1]]) / speed_h if speed_h > 1e-9 else np.array([1.0, 0.0])
            x_down = (pts[:, :2] - self._src[i, :2]) @ e
            on = x_down <= u * (self._t - s.start_s)
            if math.isfinite(s.stop_s):
                on &= x_down >= u * (self._t - s.stop_s)
            total += np.where(on, c, 0.0)
        return float(total[0]) if single else total

    def slice_grid(
        self, z: float, x_range: tuple[float, float], y_range: tuple[float, float], n: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Horizontal slice at NED depth ``z`` [m]: returns xs (n,), ys (n,), C (n,n)
        with C[i, j] the concentration [mg/m^3] at (xs[i], ys[j], z)."""
        return _slice(self.concentration, z, x_range, y_range, n)


def _slice(conc_fn, z, x_range, y_range, n):
    xs = np.linspace(x_range[0], x_range[1], n)
    ys = np.linspace(y_range[0], y_range[1], n)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    pts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, float(z))])
    return xs, ys, np.asarray(conc_fn(pts)).reshape(n, n)


@dataclass
class _AxisCalibration:
    """Per-axis dispersion parameters at a given reference speed (see module docstring)."""

    meander_sigma: float  # m/s
    inv_lagrangian_time: float  # 1/s (0 = frozen)
    small_scale_rate: float  # m^2/s, variance growth rate of random walk + puff growth


def _axis_calibration(
    coeffs: tuple[float, float, float], u: float, frozen_var: float = 0.0
) -> _AxisCalibration:
    """Dispersion parameters for Briggs ``coeffs`` = (a, b, p) at reference speed u [m/s].

    frozen_var: variance [(m/s)^2] of Taylor-frozen wind turbulence on this axis; puffs ride
    along with the frozen field, so it acts like meander and is taken out of its budget.
    """
    a, b, p = coeffs
    # First-order match of Taylor's curve to the Briggs bend (1 + b x)^p.
    inv_t = 0.0 if b == 0.0 else (3.0 * b * u if p == -0.5 else 6.0 * b * u)
    return _AxisCalibration(
        meander_sigma=math.sqrt(max(MEANDER_FRACTION * (a * u) ** 2 - frozen_var, 0.0)),
        inv_lagrangian_time=inv_t,
        small_scale_rate=a * a * DIFFUSIVE_LENGTH_M * u,
    )


def _frozen_turbulence_variances(wind: object) -> tuple[float, float]:
    """(crosswind, vertical) variance [(m/s)^2] of Taylor-frozen turbulence in ``wind``.

    Duck-typed on ``sitl.world.wind.WindField``; any other wind model counts as turbulence-free.
    Turbulence sampled as a pure time series (taylor=False) decorrelates within seconds
    along a puff path and is left in (it adds a little small-scale spread).
    """
    turb = getattr(wind, "turbulence", None)
    if turb is None or not getattr(turb, "taylor", False):
        return 0.0, 0.0
    u = float(getattr(wind, "turbulence_mean_speed_ms", 0.0))
    variances = turb.resolved_variances(u)
    return float(variances[1]), float(variances[2])


def _make_modes(
    rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """n random Fourier modes: wavevectors (n,2) [rad/m], phases (n,) [rad], frequencies
    (n,) in units of 1/T_L, and a random unit vector (2n,) of cos/sin weights."""
    lo, hi = MEANDER_WAVELENGTH_RANGE_M
    # Stratified directions and wavelengths (randomly paired) so even a handful of
    # modes covers all directions/scales and time averages converge.
    theta = 2.0 * math.pi * (np.arange(n) + rng.random(n)) / n
    frac = (rng.permutation(n) + rng.random(n)) / n
    lam = np.exp(np.log(lo) + (np.log(hi) - np.log(lo)) * frac)
    k = (2.0 * math.pi / lam)[:, None] * np.column_stack([np.cos(theta), np.sin(theta)])
    # Exponential Lagrangian correlation <=> Cauchy-distributed frequencies; use
    # stratified quantiles for a faithful correlation with few modes.
    omega_hat = np.tan(math.pi * ((rng.permutation(n) + 0.5) / n - 0.5))
    phase = rng.uniform(0.0, 2.0 * math.pi, n)
    return k, phase, omega_hat, rng.standard_normal(2 * n)


class _MeanderField:
    """Smooth random velocity field with unit variance per component (north, east, up).

    Sum of random Fourier modes over horizontal position: N_MEANDER_MODES_H modes for the
    horizontal components, N_MEANDER_MODES_V for the vertical one. The field is frozen in
    a frame advected with the reference mean wind (Taylor) and its modes drift in phase
    on the Lagrangian time scale of their axis.
    """

    def __init__(self, rng_h: np.random.Generator, rng_v: np.random.Generator):
        kh, ph, oh, wh = _make_modes(rng_h, N_MEANDER_MODES_H)
        kv, pv, ov, _ = _make_modes(rng_v, N_MEANDER_MODES_V)
        nh, nv = N_MEANDER_MODES_H, N_MEANDER_MODES_V
        self.k = np.vstack([kh, kv])
        self.phase = np.concatenate([ph, pv])
        self.omega_hat = np.concatenate([oh, ov])
        self.vertical = np.r_[np.zeros(nh, bool), np.ones(nv, bool)]
        m = nh + nv
        # Amplitudes: rows = [cos of every mode, sin of every mode], columns = (n, e, up).
        # Orthonormal weight vectors make the components uncorrelated; each cos/sin term
        # has mean square 1/2, hence the sqrt(2) for unit variance.
        q, _ = np.linalg.qr(rng_h.standard_normal((2 * nh, 2)))
        qv = rng_v.standard_normal(2 * nv)
        qv /= np.linalg.norm(qv)
        amp = np.zeros((2 * m, 3))
        amp[np.r_[0:nh, m : m + nh], 0:2] = math.sqrt(2.0) * q
        amp[np.r_[nh:m, m + nh : 2 * m], 2] = math.sqrt(2.0) * qv
        self.amp = amp
        self.offset = np.zeros(2)  # frame displacement [m], integral of the mean wind

    def advance(self, wind_xy: np.ndarray, inv_t_h: float, inv_t_v: float, h: float) -> None:
        """Move the frozen frame with ``wind_xy`` [m/s] and evolve phases over ``h`` [s]."""
        self.offset += wind_xy * h
        rate = np.where(self.vertical, inv_t_v, inv_t_h)
        self.phase += self.omega_hat * rate * h
        # Keep phases bounded so long runs do not lose precision.
        np.mod(self.phase, 2.0 * math.pi, out=self.phase)

    def unit(self, xy: np.ndarray) -> np.ndarray:
        """Unit-variance field (K,3) (north, east, up) at horizontal NED points xy (K,2) [m]."""
        xy = np.ascontiguousarray(xy, dtype=float)
        out = np.empty((len(xy), 3))
        for i in range(len(xy)):
            _meander_at(xy[i, 0], xy[i, 1], self.offset, self.k, self.phase, self.amp, out[i])
        return out


# ---------------------------------------------------------------------------------- kernels
# The puff update and the concentration sum are the plume's hot loops (called at the plume
# and sensor rates inside a simulator that must run >= 100x real time): fused numba loops,
# no (K,M) or (N,K) temporaries. Per-puff arithmetic is the formula of the docstrings above.


@njit(cache=True)
def _meander_at(
    x: float, y: float, offset: np.ndarray, k: np.ndarray, phase: np.ndarray, amp: np.ndarray, out: np.ndarray
) -> None:
    """Unit-variance meander (north, east, up) at horizontal NED point (x, y) [m] into ``out`` (3,).

    offset (2,): frame displacement [m]; k (M,2) [rad/m]; phase (M,) [rad]; amp (2M,3): cos
    rows then sin rows (see ``_MeanderField``)."""
    m = phase.shape[0]
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    dx = x - offset[0]
    dy = y - offset[1]
    for j in range(m):
        arg = dx * k[j, 0] + dy * k[j, 1] + phase[j]
        c = math.cos(arg)
        s = math.sin(arg)
        for a in range(3):
            out[a] += c * amp[j, a] + s * amp[m + j, a]


@njit(cache=True)
def _advance_puffs(
    pos: np.ndarray,
    r2: np.ndarray,
    unit: np.ndarray,
    refresh: np.ndarray,
    vel: np.ndarray,
    noise: np.ndarray,
    scale: np.ndarray,
    walk: np.ndarray,
    growth: float,
    h: float,
    offset: np.ndarray,
    k: np.ndarray,
    phase: np.ndarray,
    amp: np.ndarray,
) -> None:
    """One puff substep of ``h`` [s], in place.

    pos (K,3): x, y NED and unfolded altitude (up) [m]; r2 (K,) [m^2]; unit (K,3): cached
    unit meander, re-sampled at the pre-step position where ``refresh`` (K,) is True or the
    cache is NaN; vel (K,3): wind NED [m/s] at the physical puff positions; noise (K,3):
    standard normals; scale (3,): meander sigma per axis [m/s]; walk (3,): random-walk step
    standard deviation [m]; growth: r^2 growth rate [m^2/s]; offset/k/phase/amp: meander."""
    n = pos.shape[0]
    for i in range(n):
        if refresh[i] or math.isnan(unit[i, 0]):
            _meander_at(pos[i, 0], pos[i, 1], offset, k, phase, amp, unit[i])
        # Vertical in the unfolded coordinate: NED velocity is down, altitude is up.
        pos[i, 0] += (vel[i, 0] + unit[i, 0] * scale[0]) * h + noise[i, 0] * walk[0]
        pos[i, 1] += (vel[i, 1] + unit[i, 1] * scale[1]) * h + noise[i, 1] * walk[1]
        pos[i, 2] += (-vel[i, 2] + unit[i, 2] * scale[2]) * h + noise[i, 2] * walk[2]
        r2[i] += growth * h


@njit(cache=True)
def _puff_concentration(pts: np.ndarray, pos: np.ndarray, r2: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Sum of ground-reflected isotropic Gaussian puffs [mg/m^3] at NED points pts (N,3) [m].

    pos (K,3): x, y NED and unfolded altitude [m] (|altitude| is physical); r2 (K,) puff
    variance [m^2]; mass (K,) [g]."""
    n = pts.shape[0]
    kp = pos.shape[0]
    out = np.zeros(n)
    inv = np.empty(kp)
    norm = np.empty(kp)
    for j in range(kp):
        inv[j] = -0.5 / r2[j]
        norm[j] = mass[j] * _G_TO_MG / (_TWO_PI_POW_1_5 * r2[j] * math.sqrt(r2[j]))
    for i in range(n):
        zq = -pts[i, 2]
        acc = 0.0
        for j in range(kp):
            dx = pts[i, 0] - pos[j, 0]
            dy = pts[i, 1] - pos[j, 1]
            dh2 = dx * dx + dy * dy
            zp = abs(pos[j, 2])
            e = dh2 * inv[j]
            # A puff whose horizontal factor is below e^-40 adds < 5e-18 of its peak: skipping
            # it saves the two exp calls (most puffs are far from a point) at no visible cost.
            if e < -40.0:
                continue
            dzm = zq - zp
            dzp = zq + zp
            acc += norm[j] * (math.exp(e + dzm * dzm * inv[j]) + math.exp(e + dzp * dzp * inv[j]))
        out[i] = acc
    return out


class PuffPlume:
    """Instantaneous puff (filament) plume, Farrell et al. (2002) style.

    State: puff centres (x, y NED [m] and an *unfolded* altitude [m] whose absolute
    value is the physical altitude: reflection at the ground, the puff analogue of the
    image source), puff variances r^2 [m^2], masses [g], release times [s].
    """

    def __init__(
        self,
        config: PlumeConfig,
        wind: WindLike,
        seed: int | np.random.SeedSequence,
        t0: float = 0.0,
    ):
        """config: plume configuration (validated, ValueError lists the problems);
        wind: object with ``mean(t, pos)`` and ``velocity(t, positions)``;
        seed: int or SeedSequence for every random process; t0: initial time [s]."""
        _check(config)
        self.config = config
        self._wind = wind
        ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        ss_walk, ss_modes_h, ss_modes_v = ss.spawn(3)
        self._rng = np.random.default_rng(ss_walk)
        self._meander = _MeanderField(
            np.random.default_rng(ss_modes_h), np.random.default_rng(ss_modes_v)
        )
        # Each puff re-samples the meander every MEANDER_REFRESH_S, a 1/n_groups share of
        # the puffs per substep (constant cost per step).
        self._n_groups = max(1, round(MEANDER_REFRESH_S * config.update_rate_hz))
        self._substep_count = 0
        self._next_serial = 0
        self._src = np.array([s.position_ned for s in config.sources], dtype=float)
        self._puff_mass_g = np.array([s.rate_g_s / config.puff_rate_hz for s in config.sources])
        self._n_released = np.zeros(len(config.sources), dtype=np.int64)
        self._t = float(t0)
        self._cy = _BRIGGS_Y[config.stability]
        self._cz = _BRIGGS_Z[config.stability]
        self._frozen_var = (
            _frozen_turbulence_variances(wind) if config.subtract_wind_turbulence else (0.0, 0.0)
        )
        if config.domain_min_ned is not None:
            self._dom_lo = np.asarray(config.domain_min_ned, dtype=float)
            self._dom_hi = np.asarray(config.domain_max_ned, dtype=float)
        else:
            self._dom_lo = self._dom_hi = None
        self._pos = np.zeros((0, 3))  # x, y NED, unfolded altitude (up) [m]
        self._r2 = np.zeros(0)
        self._mass = np.zeros(0)
        self._t_rel = np.zeros(0)
        self._serial = np.zeros(0, dtype=np.int64)
        self._unit_meander = np.zeros((0, 3))
        self.released_mass_g = 0.0
        self.removed_domain_mass_g = 0.0
        self.removed_cap_mass_g = 0.0

    # ------------------------------------------------------------------ state
    @property
    def t(self) -> float:
        """Current plume time [s]."""
        return self._t

    @property
    def puffs(self) -> np.ndarray:
        """(K,4) array: x, y, z (NED, physical) [m] and r^2 [m^2] of every live puff."""
        return np.column_stack(
            [self._pos[:, 0], self._pos[:, 1], -np.abs(self._pos[:, 2]), self._r2]
        )

    @property
    def puff_release_times(self) -> np.ndarray:
        """(K,) release time [s] of every live puff (same order as ``puffs``)."""
        return self._t_rel.copy()

    @property
    def mass_in_puffs_g(self) -> float:
        """Mass currently carried by live puffs [g]."""
        return float(self._mass.sum())

    @property
    def removed_mass_g(self) -> float:
        """Mass removed at the domain edge or by the puff cap [g]."""
        return self.removed_domain_mass_g + self.removed_cap_mass_g

    def _ref_speed(self, t: float) -> tuple[np.ndarray, float]:
        w = np.asarray(self._wind.mean(t, self._src[0]), dtype=float)
        return w, max(math.hypot(w[0], w[1]), self.config.min_wind_speed_m_s)

    # ------------------------------------------------------------------ dynamics
    def step(self, t: float, dt: float) -> None:
        """Advance the puffs from ``t`` to ``t + dt`` [s] (substeps <= 1/update_rate_hz)."""
        if dt <= 0.0:
            return
        n_sub = max(1, math.ceil(dt * self.config.update_rate_hz - 1e-9))
        h = dt / n_sub
        for i in range(n_sub):
            self._substep(t + i * h, h)
        self._t = t + dt

    def _release(self, t: float, h: float) -> None:
        cfg = self.config
        new_pos, new_t, new_m = [], [], []
        for i, s in enumerate(cfg.sources):
            if s.rate_g_s <= 0.0:
                continue
            # Release times start_s + k/puff_rate_hz that fall in [t, t+h) and < stop_s.
            k0 = max(self._n_released[i], math.ceil((t - s.start_s) * cfg.puff_rate_hz - 1e-9))
            k1 = math.ceil((min(t + h, s.stop_s) - s.start_s) * cfg.puff_rate_hz - 1e-9)
            if k1 <= k0:
                continue
            n = k1 - k0
            self._n_released[i] = k1
            p = np.empty((n, 3))
            p[:, :2] = self._src[i, :2]
            p[:, 2] = -self._src[i, 2]
            new_pos.append(p)
            new_t.append(s.start_s + np.arange(k0, k1) / cfg.puff_rate_hz)
            new_m.append(np.full(n, self._puff_mass_g[i]))
        if not new_pos:
            return
        m = np.concatenate(new_m)
        pos = np.concatenate(new_pos)
        self.released_mass_g += float(m.sum())
        self._serial = np.concatenate(
            [self._serial, np.arange(self._next_serial, self._next_serial + len(m))]
        )
        self._next_serial += len(m)
        # New puffs get their meander sample in this substep's refresh (see _substep).
        self._unit_meander = np.concatenate([self._unit_meander, np.full((len(m), 3), np.nan)])
        self._pos = np.concatenate([self._pos, pos])
        self._t_rel = np.concatenate([self._t_rel, *new_t])
        self._mass = np.concatenate([self._mass, m])
        self._r2 = np.concatenate([self._r2, np.full(len(m), cfg.source_radius_m**2)])

    def _substep(self, t: float, h: float) -> None:
        self._release(t, h)
        w_ref, u = self._ref_speed(t)
        cal_y = _axis_calibration(self._cy, u, self._frozen_var[0])
        cal_z = _axis_calibration(self._cz, u, self._frozen_var[1])
        k = len(self._r2)
        if k:
            # The meander is smooth and nearly frozen in the frame the puffs ride in, so
            # a puff's sample changes slowly: refresh each puff every MEANDER_REFRESH_S.
            # (New puffs have a NaN cache and are sampled in the same pass.)
            refresh = self._serial % self._n_groups == self._substep_count % self._n_groups
            phys = self._pos.copy()
            phys[:, 2] = -np.abs(phys[:, 2])
            vel = np.ascontiguousarray(self._wind.velocity(t, phys), dtype=float).reshape(k, 3)
            growth = PUFF_GROWTH_SHARE * min(cal_y.small_scale_rate, cal_z.small_scale_rate)
            walk_y = math.sqrt(max(cal_y.small_scale_rate - growth, 0.0) * h)
            walk_z = math.sqrt(max(cal_z.small_scale_rate - growth, 0.0) * h)
            scale = np.array([cal_y.meander_sigma, cal_y.meander_sigma, cal_z.meander_sigma])
            noise = self._rng.standard_normal((k, 3))
            mf = self._meander
            _advance_puffs(
                self._pos, self._r2, self._unit_meander, refresh, vel, noise, scale,
                np.array([walk_y, walk_y, walk_z]), growth, h, mf.offset, mf.k, mf.phase, mf.amp,
            )  # fmt: skip
            self._remove()
        self._meander.advance(w_ref[:2], cal_y.inv_lagrangian_time, cal_z.inv_lagrangian_time, h)
        self._substep_count += 1

    def _keep(self, mask: np.ndarray) -> None:
        self._pos = self._pos[mask]
        self._r2 = self._r2[mask]
        self._mass = self._mass[mask]
        self._t_rel = self._t_rel[mask]
        self._serial = self._serial[mask]
        self._unit_meander = self._unit_meander[mask]

    def _remove(self) -> None:
        if self._dom_lo is not None:
            phys = np.column_stack([self._pos[:, :2], -np.abs(self._pos[:, 2])])
            inside = np.all((phys >= self._dom_lo) & (phys <= self._dom_hi), axis=1)
            if not inside.all():
                self.removed_domain_mass_g += float(self._mass[~inside].sum())
                self._keep(inside)
        excess = len(self._r2) - self.config.max_puffs
        if excess > 0:
            # Puffs are stored in release order, so the first ones are the oldest.
            self.removed_cap_mass_g += float(self._mass[:excess].sum())
            self._keep(slice(excess, None))

    # ------------------------------------------------------------------ output
    def concentration(self, points: np.ndarray) -> np.ndarray | float:
        """Concentration [mg/m^3] at (N,3) NED points -> (N,), or (3,) -> float."""
        pts = np.asarray(points, dtype=float)
        single = pts.ndim == 1
        pts = np.atleast_2d(pts)
        out = _puff_concentration(np.ascontiguousarray(pts), self._pos, self._r2, self._mass)
        return float(out[0]) if single else out

    def slice_grid(
        self, z: float, x_range: tuple[float, float], y_range: tuple[float, float], n: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Horizontal slice at NED depth ``z`` [m]: returns xs (n,), ys (n,), C (n,n)
        with C[i, j] the concentration [mg/m^3] at (xs[i], ys[j], z)."""
        return _slice(self.concentration, z, x_range, y_range, n)


def make_plume(
    config: PlumeConfig, wind: WindLike, seed: int | np.random.SeedSequence, t0: float = 0.0
) -> PuffPlume | GaussianPlume:
    """Build the plume model named by ``config.model`` (ValueError if config is invalid)."""
    _check(config)
    if config.model == "gaussian":
        return GaussianPlume(config, wind, seed, t0)
    return PuffPlume(config, wind, seed, t0)
