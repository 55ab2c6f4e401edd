"""Orthogonal phase-optimized multisine inputs (Morelli's design, SIDPAC ``mkmsswp``).

References:
- E. A. Morelli, "Multiple input design for real-time parameter estimation in the frequency
  domain", 13th IFAC Symposium on System Identification, 2003.
- V. Klein, E. A. Morelli, *Aircraft System Identification: Theory and Practice*, AIAA, 2006,
  ch. 9.4 (multisine inputs, relative peak factor).
- M. R. Schroeder, "Synthesis of low-peak-factor signals and binary sequences with low
  autocorrelation", IEEE Trans. Inf. Theory 16(1), 1970 (the starting phases).
- E. Van der Ouderaa, J. Schoukens, J. Renneboog, "Peak factor minimization using a time-frequency
  domain swapping algorithm", IEEE Trans. Instrum. Meas. 37(1), 1988 (the clipping iteration).

Design, for ``m`` inputs over ``T`` seconds sampled every ``dt`` seconds:

- the harmonics ``f_k = k / T`` (Hz) inside ``[f_min, f_max]`` are dealt to the inputs in turn
  (input ``j`` gets the ``j``-th, ``j + m``-th, ... harmonic), so no two inputs share a frequency and
  the inputs are mutually orthogonal over ``T`` (and over the samples ``t = 0, dt, ..., T``);
- input ``j`` is ``u_j(t) = sum_k a_k cos(2 pi f_k t + phi_k)`` with equal amplitudes ``a_k``
  within an input (uniform power over its band);
- the phases start from Schroeder's phases (plus a small seeded perturbation) and are improved by
  the clipping iteration: synthesize, clip at the level of a sinusoid of the same power, take the
  phases of the clipped signal's discrete Fourier transform at the input's own harmonics, repeat,
  keep the best. The figure of merit is Morelli's relative peak factor
  ``RPF = (max u - min u) / (2 sqrt(2) rms(u))`` (1 for a single sinusoid);
- each input is then shifted in time to an upward zero crossing, so it starts at zero and, being
  periodic in ``T``, ends at zero at ``t = T``; a time shift keeps the frequencies, the amplitudes
  and the orthogonality;
- finally each input is scaled so that its largest sampled magnitude is its peak amplitude.

The peak factors and peaks are those of the samples at ``dt``. ``Multisine.at`` evaluates the same
sum of sines at any time (the signal is periodic with period ``T``); between the design samples it
can exceed the sampled peak slightly: measured for 4 inputs at 0.1-2 Hz over 120 s, up to 2 % with
10 samples per period of ``f_max``, 1 % with 20, 0.1 % with 50 (design at the fastest rate you use).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

#: Clipping iterations per input, and the number of iterations without improvement that ends them early.
ITERATIONS = 1000
PATIENCE = 250
#: Half-width (rad) of the seeded uniform perturbation added to Schroeder's phases.
START_PERTURBATION_RAD = math.pi / 4


@dataclass(frozen=True, eq=False)
class Multisine:
    """A designed multisine: samples and the sum-of-sines description behind them.

    Attributes:
        t: sample times (s), ``0, dt, ..., T`` (``n_samples = T / dt + 1``).
        u: inputs (n_samples, n_inputs), in the units of the peak amplitudes.
        frequencies_hz: per input, the frequencies of its components (Hz).
        component_amplitudes: per input, the amplitude of each component (input units).
        phases_rad: per input, the phase of each component (rad), in ``a cos(2 pi f t + phi)``.
        relative_peak_factor: per input, ``(max u - min u) / (2 sqrt(2) rms(u))`` over one period of
            the samples (1 for a single sinusoid; lower is better).
        duration_s: the period ``T`` (s).
        dt_s: the sample interval (s).
    """

    t: np.ndarray
    u: np.ndarray
    frequencies_hz: tuple[np.ndarray, ...]
    component_amplitudes: tuple[np.ndarray, ...]
    phases_rad: tuple[np.ndarray, ...]
    relative_peak_factor: np.ndarray
    duration_s: float
    dt_s: float

    @property
    def n_inputs(self) -> int:
        return len(self.frequencies_hz)

    def at(self, t: float | np.ndarray) -> np.ndarray:
        """The inputs at times ``t`` (s): shape (n_inputs,) for a scalar time, (len(t), n_inputs) for
        a 1-D array. The same sum of sines as the design, so a controller running at another rate can
        sample it; periodic with period ``duration_s`` (window it yourself outside ``[0, T]``)."""
        tt = np.asarray(t, dtype=float)
        if tt.ndim > 1:
            raise ValueError(f"t must be a scalar or 1-D, got shape {tt.shape}")
        out = _sum_of_sines(np.atleast_1d(tt), self.frequencies_hz, self.component_amplitudes, self.phases_rad)
        return out[0] if tt.ndim == 0 else out


def relative_peak_factor(u: np.ndarray) -> float:
    """Morelli's relative peak factor of one signal (Klein & Morelli 2006, ch. 9.4):
    ``(max u - min u) / (2 sqrt(2) rms(u))``; 1 for a sinusoid, ``1 / sqrt(2)`` for a square wave."""
    x = np.asarray(u, dtype=float)
    rms = math.sqrt(float(np.mean(x * x)))
    if not rms > 0.0:
        raise ValueError("relative peak factor of an all-zero signal is undefined")
    return float(np.ptp(x)) / (2.0 * math.sqrt(2.0) * rms)


def design_multisine(
    n_inputs: int,
    duration_s: float,
    dt_s: float,
    f_min_hz: float,
    f_max_hz: float,
    *,
    amplitudes: Sequence[float] | None = None,
    seed: int = 0,
) -> Multisine:
    """Design ``n_inputs`` mutually orthogonal phase-optimized multisines (see the module docstring).

    Args:
        n_inputs: number of inputs (e.g. 4 virtual actuators).
        duration_s: period ``T`` (s); the lowest possible frequency is ``1 / T``.
        dt_s: sample interval (s); ``T / dt`` must be an integer and ``f_max`` below ``1 / (2 dt)``.
        f_min_hz, f_max_hz: the band (Hz); the harmonics ``k / T`` inside it are used.
        amplitudes: peak amplitude of each input (input units), default 1 for all.
        seed: picks the perturbation of the starting phases; the same arguments and seed give the same
            signals, another seed another (equally valid) phase set, e.g. for a validation manoeuvre.

    Raises:
        ValueError: on a bad argument, or a band with fewer harmonics than inputs.
    """
    n_samples = _period_samples(duration_s, dt_s)
    peaks = _peak_amplitudes(n_inputs, amplitudes)
    harmonics = _deal_harmonics(n_inputs, duration_s, n_samples, f_min_hz, f_max_hz)
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples + 1) * dt_s
    freqs: list[np.ndarray] = []
    amps: list[np.ndarray] = []
    phases: list[np.ndarray] = []
    for j, k in enumerate(harmonics):
        a = np.ones(k.size)
        phi0 = _schroeder_phases(a) + rng.uniform(-START_PERTURBATION_RAD, START_PERTURBATION_RAD, k.size)
        phi = _optimize_phases(k, a, phi0, n_samples)
        phi = _shift_to_zero(k, a, phi, n_samples)
        u = _evaluate(t / duration_s, k, a, phi)
        scale = peaks[j] / float(np.max(np.abs(u)))
        freqs.append(k / duration_s)
        amps.append(a * scale)
        phases.append(phi)
    u_all = _sum_of_sines(t, freqs, amps, phases)
    rpf = np.array([relative_peak_factor(u_all[:-1, j]) for j in range(n_inputs)])
    for arr in (t, u_all, rpf, *freqs, *amps, *phases):
        arr.setflags(write=False)
    return Multisine(
        t=t,
        u=u_all,
        frequencies_hz=tuple(freqs),
        component_amplitudes=tuple(amps),
        phases_rad=tuple(phases),
        relative_peak_factor=rpf,
        duration_s=float(duration_s),
        dt_s=float(dt_s),
    )


def _sum_of_sines(
    t: np.ndarray, freqs: Sequence[np.ndarray], amps: Sequence[np.ndarray], phases: Sequence[np.ndarray]
) -> np.ndarray:
    """Inputs (len(t), n_inputs) at times ``t`` (s): ``u_j = sum_k a_jk cos(2 pi f_jk t + phi_jk)``."""
    out = np.empty((t.size, len(freqs)))
    for j, (f, a, phi) in enumerate(zip(freqs, amps, phases, strict=True)):
        out[:, j] = np.cos(np.multiply.outer(t, 2.0 * np.pi * f) + phi) @ a
    return out


def _period_samples(duration_s: float, dt_s: float) -> int:
    if not (math.isfinite(duration_s) and duration_s > 0.0 and math.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError(f"duration_s and dt_s must be positive and finite, got {duration_s}, {dt_s}")
    n = round(duration_s / dt_s)
    if n < 4 or abs(n * dt_s - duration_s) > 1e-9 * duration_s:
        raise ValueError(f"duration_s / dt_s must be an integer >= 4, got {duration_s} / {dt_s}")
    return int(n)


def _peak_amplitudes(n_inputs: int, amplitudes: Sequence[float] | None) -> np.ndarray:
    if n_inputs < 1:
        raise ValueError(f"n_inputs must be >= 1, got {n_inputs}")
    if amplitudes is None:
        return np.ones(n_inputs)
    peaks = np.asarray(amplitudes, dtype=float)
    if peaks.shape != (n_inputs,):
        raise ValueError(f"amplitudes needs one peak amplitude per input ({n_inputs}), got {len(peaks)}")
    if not np.all(np.isfinite(peaks) & (peaks > 0.0)):
        raise ValueError(f"amplitudes must be positive and finite, got {list(peaks)}")
    return peaks


def _deal_harmonics(n_inputs: int, duration_s: float, n_samples: int, f_min: float, f_max: float) -> list[np.ndarray]:
    """Harmonic numbers ``k`` (f = k / T) in the band, dealt to the inputs in turn."""
    if not (math.isfinite(f_min) and math.isfinite(f_max) and 0.0 <= f_min < f_max):
        raise ValueError(f"need 0 <= f_min_hz < f_max_hz, got {f_min}, {f_max}")
    k_lo = max(1, math.ceil(f_min * duration_s - 1e-9))
    k_hi = math.floor(f_max * duration_s + 1e-9)
    if 2 * k_hi >= n_samples:
        raise ValueError(f"f_max_hz {f_max} is not below the Nyquist frequency {n_samples / (2 * duration_s)} Hz")
    k = np.arange(k_lo, k_hi + 1)
    if k.size < n_inputs:
        raise ValueError(
            f"the band {f_min}-{f_max} Hz holds {k.size} harmonics of 1/T = {1 / duration_s:.4g} Hz, "
            f"fewer than the {n_inputs} inputs: widen the band or lengthen the duration"
        )
    return [k[j::n_inputs] for j in range(n_inputs)]


def _schroeder_phases(a: np.ndarray) -> np.ndarray:
    """Schroeder's low-peak-factor phases for component powers ``a^2`` (Schroeder 1970; Klein & Morelli
    ch. 9.4): ``phi_k = -2 pi sum_{i<k} (k - i) p_i`` with ``p_i`` the power fractions."""
    p = a**2 / np.sum(a**2)
    k = np.arange(a.size)
    return np.array([-2.0 * np.pi * np.sum((kk - k[:kk]) * p[:kk]) for kk in k])


def _synthesize(k: np.ndarray, a: np.ndarray, phi: np.ndarray, n: int) -> np.ndarray:
    """One period on the ``n`` design samples by inverse FFT: ``sum a cos(2 pi k i / n + phi)``."""
    spectrum = np.zeros(n // 2 + 1, dtype=complex)
    spectrum[k] = 0.5 * n * a * np.exp(1j * phi)
    return np.fft.irfft(spectrum, n)


def _optimize_phases(k: np.ndarray, a: np.ndarray, phi: np.ndarray, n: int) -> np.ndarray:
    """Clipping iteration (Van der Ouderaa et al. 1988): clip at the peak of a sinusoid of the same
    power, keep the clipped signal's phases at the harmonics ``k``; return the best phases seen."""
    level = math.sqrt(float(np.sum(a**2)))  # sqrt(2) * rms of the multisine
    best_phi, best = phi, math.inf
    stale = 0
    for _ in range(ITERATIONS):
        u = _synthesize(k, a, phi, n)
        rpf = relative_peak_factor(u)
        if rpf < best - 1e-9:
            best_phi, best, stale = phi, rpf, 0
        else:
            stale += 1
            if stale >= PATIENCE:
                break
        phi = np.angle(np.fft.rfft(np.clip(u, -level, level))[k])
    return np.asarray(best_phi)


def _evaluate(x: np.ndarray | float, k: np.ndarray, a: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """``sum a cos(2 pi k x + phi)`` at fractions ``x`` of the period."""
    return np.cos(np.multiply.outer(x, 2.0 * np.pi * k) + phi) @ a


def _shift_to_zero(k: np.ndarray, a: np.ndarray, phi: np.ndarray, n: int) -> np.ndarray:
    """Phases of the same signal shifted in time to its first upward zero crossing, so it starts (and,
    periodic, ends) at zero; the shift ``x0`` (fraction of the period) adds ``2 pi k x0`` to the phases."""

    def g(x: float) -> float:
        return float(_evaluate(x, k, a, phi))

    u = _synthesize(k, a, phi, n)
    for i in np.nonzero((u <= 0.0) & (np.roll(u, -1) > 0.0))[0]:  # a zero-mean signal has some
        lo, hi = i / n, (i + 1) / n
        if g(lo) <= 0.0 < g(hi):  # the FFT and the direct sum can disagree in sign at round-off level
            x0 = brentq(g, lo, hi, xtol=1e-15)
            break
    else:
        raise RuntimeError("no upward zero crossing found")  # unreachable for a zero-mean, non-zero signal
    return np.angle(np.exp(1j * (phi + 2.0 * np.pi * k * x0)))
