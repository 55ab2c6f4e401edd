"""The puff plume's large-scale meander and its calibration against Pasquill-Gifford / Briggs.

See :mod:`sitl.world.plume` for the model; units m, s, m/s; NED.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

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


@dataclass
class AxisCalibration:
    """Per-axis dispersion parameters at a given reference speed (see module docstring)."""

    meander_sigma: float  # m/s
    inv_lagrangian_time: float  # 1/s (0 = frozen)
    small_scale_rate: float  # m^2/s, variance growth rate of random walk + puff growth


def axis_calibration(
    coeffs: tuple[float, float, float], u: float, frozen_var: float = 0.0
) -> AxisCalibration:
    """Dispersion parameters for Briggs ``coeffs`` = (a, b, p) at reference speed u [m/s].

    frozen_var: variance [(m/s)^2] of Taylor-frozen wind turbulence on this axis; puffs ride
    along with the frozen field, so it acts like meander and is taken out of its budget.
    """
    a, b, p = coeffs
    # First-order match of Taylor's curve to the Briggs bend (1 + b x)^p.
    inv_t = 0.0 if b == 0.0 else (3.0 * b * u if p == -0.5 else 6.0 * b * u)
    return AxisCalibration(
        meander_sigma=math.sqrt(max(MEANDER_FRACTION * (a * u) ** 2 - frozen_var, 0.0)),
        inv_lagrangian_time=inv_t,
        small_scale_rate=a * a * DIFFUSIVE_LENGTH_M * u,
    )


def frozen_turbulence_variances(wind: object) -> tuple[float, float]:
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


def make_modes(
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


class MeanderField:
    """Smooth random velocity field with unit variance per component (north, east, up).

    Sum of random Fourier modes over horizontal position: N_MEANDER_MODES_H modes for the
    horizontal components, N_MEANDER_MODES_V for the vertical one. The field is frozen in
    a frame advected with the reference mean wind (Taylor) and its modes drift in phase
    on the Lagrangian time scale of their axis.
    """

    def __init__(self, rng_h: np.random.Generator, rng_v: np.random.Generator):
        kh, ph, oh, wh = make_modes(rng_h, N_MEANDER_MODES_H)
        kv, pv, ov, _ = make_modes(rng_v, N_MEANDER_MODES_V)
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
            meander_at(xy[i, 0], xy[i, 1], self.offset, self.k, self.phase, self.amp, out[i])
        return out


@njit(cache=True)
def meander_at(
    x: float, y: float, offset: np.ndarray, k: np.ndarray, phase: np.ndarray, amp: np.ndarray, out: np.ndarray
) -> None:
    """Unit-variance meander (north, east, up) at horizontal NED point (x, y) [m] into ``out`` (3,).

    offset (2,): frame displacement [m]; k (M,2) [rad/m]; phase (M,) [rad]; amp (2M,3): cos
    rows then sin rows (see ``MeanderField``)."""
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
