"""IEC 61400-1 Kaimal turbulence, synthesized once as periodic series by the exact spectral method.

The three components (u' along the mean wind, v' crosswind, w' vertical), m/s; spectra in
(m/s)^2/Hz; every random draw from the ``np.random.Generator`` the caller passes (seeded).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from sitl.world.wind.steady import check_finite

# IEC 61400-1 reference turbulence intensities (at 15 m/s) per turbine class letter.
IEC_I_REF: dict[str, float] = {"A": 0.16, "B": 0.14, "C": 0.12}

# The Kaimal spectrum uses L/U; a floor keeps it finite in calm air.
MIN_ADVECTION_SPEED_MS = 1.0


def kaimal_psd(
    f: np.ndarray | float, sigma: float, length_scale: float, mean_speed: float
) -> np.ndarray:
    """One-sided Kaimal PSD ((m/s)^2/Hz) at frequencies ``f`` (Hz), IEC 61400-1 form.

    ``S(f) = 4 sigma^2 (L/U) / (1 + 6 f L/U)^(5/3)`` with U = max(mean_speed, 1 m/s).
    ``sigma`` in m/s, ``length_scale`` L in m.
    """
    u = max(float(mean_speed), MIN_ADVECTION_SPEED_MS)
    tl = float(length_scale) / u
    f_arr = np.asarray(f, dtype=np.float64)
    return 4.0 * sigma**2 * tl / (1.0 + 6.0 * f_arr * tl) ** (5.0 / 3.0)


@dataclass(frozen=True)
class KaimalTurbulence:
    """IEC 61400-1 Kaimal turbulence, synthesized as a periodic series of ``duration_s``.

    Attributes:
        sigma_u: longitudinal standard deviation (m/s, >= 0); sigma_v = 0.8 sigma_u,
            sigma_w = 0.5 sigma_u.
        height_m: height z (m, > 0) that sets the scale parameter Lambda = 0.7 z (z < 60 m),
            42 m above; L_u = 8.1, L_v = 2.7, L_w = 0.66 Lambda.
        duration_s: length of the synthesized, periodic series (s, > 0).
        sample_rate_hz: sample rate of the series (Hz, > 0); resolves up to rate/2.
        taylor: sample the series as frozen turbulence advected by the mean wind (Taylor)
            instead of as a pure time series that is the same everywhere.
        mean_speed_ms: U used in the spectra (m/s). None: the horizontal speed of the
            steady wind's initial velocity (reference height), as chosen by :class:`WindField`.
    """

    sigma_u: float
    height_m: float = 10.0
    duration_s: float = 600.0
    sample_rate_hz: float = 50.0
    taylor: bool = True
    mean_speed_ms: float | None = None

    def __post_init__(self) -> None:
        check_finite(self.sigma_u, "sigma_u", "a finite number >= 0 (m/s)", self.sigma_u >= 0)
        check_finite(self.height_m, "height_m", "a finite height > 0 (m)", self.height_m > 0)
        check_finite(
            self.duration_s, "duration_s", "a finite duration > 0 (s)", self.duration_s > 0
        )
        check_finite(
            self.sample_rate_hz,
            "sample_rate_hz",
            "a finite rate > 0 (Hz)",
            self.sample_rate_hz > 0,
        )
        if self.n_samples < 4:
            raise ValueError(
                "duration_s * sample_rate_hz must give at least 4 samples, got "
                f"{self.duration_s} s * {self.sample_rate_hz} Hz"
            )
        if self.mean_speed_ms is not None:
            check_finite(
                self.mean_speed_ms,
                "mean_speed_ms",
                "None or a finite speed >= 0 (m/s)",
                self.mean_speed_ms >= 0,
            )
        object.__setattr__(self, "taylor", bool(self.taylor))

    @classmethod
    def from_intensity_class(
        cls, cls_letter: str, mean_speed: float, **kwargs: object
    ) -> KaimalTurbulence:
        """IEC normal turbulence model: sigma_u = I_ref (0.75 U + 5.6), I_ref A/B/C = .16/.14/.12.

        ``mean_speed`` U in m/s (hub/reference height); it is also stored as ``mean_speed_ms``
        unless given in kwargs.
        """
        letter = str(cls_letter).upper()
        if letter not in IEC_I_REF:
            raise ValueError(f"cls_letter must be one of {tuple(IEC_I_REF)}, got {cls_letter!r}")
        u = check_finite(mean_speed, "mean_speed", "a finite speed >= 0 (m/s)", mean_speed >= 0)
        kwargs.setdefault("mean_speed_ms", u)
        return cls(sigma_u=IEC_I_REF[letter] * (0.75 * u + 5.6), **kwargs)  # type: ignore[arg-type]

    @classmethod
    def from_intensity(cls, ti: float, mean_speed: float, **kwargs: object) -> KaimalTurbulence:
        """sigma_u = ti * U for a turbulence intensity ``ti`` (>= 0) and U = ``mean_speed`` m/s."""
        i = check_finite(ti, "ti", "a finite intensity >= 0", ti >= 0)
        u = check_finite(mean_speed, "mean_speed", "a finite speed >= 0 (m/s)", mean_speed >= 0)
        kwargs.setdefault("mean_speed_ms", u)
        return cls(sigma_u=i * u, **kwargs)  # type: ignore[arg-type]

    @property
    def n_samples(self) -> int:
        """Number of samples of the periodic series."""
        return int(round(self.duration_s * self.sample_rate_hz))

    def sigmas(self) -> tuple[float, float, float]:
        """Target standard deviations (m/s) of u', v', w'."""
        return (self.sigma_u, 0.8 * self.sigma_u, 0.5 * self.sigma_u)

    def length_scales(self) -> tuple[float, float, float]:
        """Kaimal integral length scales L_u, L_v, L_w (m) at ``height_m``."""
        lam = 0.7 * self.height_m if self.height_m < 60.0 else 42.0
        return (8.1 * lam, 2.7 * lam, 0.66 * lam)

    def frequencies(self) -> np.ndarray:
        """rfft frequencies (Hz) of the synthesized series."""
        return sfft.rfftfreq(self.n_samples, 1.0 / self.sample_rate_hz)

    def resolved_variances(self, mean_speed: float) -> tuple[float, float, float]:
        """Integral of each target PSD over the resolved band ((m/s)^2); the series' variances.

        Bins k = 1 .. n/2 of width df, the DC bin excluded and an even-n Nyquist bin counted
        as half a bin, which is exactly the variance the spectral synthesis yields.
        """
        return tuple(float(np.sum(w)) for w in self._bin_variances(mean_speed))  # type: ignore[return-value]

    def _bin_variances(self, mean_speed: float) -> list[np.ndarray]:
        """Per-rfft-bin variance contributions S(f_k) df (DC zero, even-n Nyquist halved)."""
        n = self.n_samples
        f = self.frequencies()
        df = self.sample_rate_hz / n
        weight = np.full(f.shape, df)
        weight[0] = 0.0  # zero-mean series: the mean wind lives in SteadyWind
        if n % 2 == 0:
            weight[-1] = 0.5 * df
        return [
            kaimal_psd(f, s, length, mean_speed) * weight
            for s, length in zip(self.sigmas(), self.length_scales(), strict=True)
        ]

    def synthesize(
        self, mean_speed: float, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Generate (t, u', v', w'): time (s) and the three components (m/s), periodic.

        Exact non-causal method: white Gaussian noise, rfft, shaped by sqrt of the target
        PSD, irfft. The realized series is then rescaled so its variance equals the target
        PSD integrated over the resolved band exactly (not only in expectation), so that a
        requested turbulence intensity is what a run gets.
        """
        n = self.n_samples
        noise = rng.standard_normal((3, n))
        out = []
        for comp_noise, bin_var in zip(noise, self._bin_variances(mean_speed), strict=True):
            target = float(np.sum(bin_var))
            if target <= 0.0:
                out.append(np.zeros(n))
                continue
            spec = sfft.rfft(comp_noise) * np.sqrt(bin_var)
            x = sfft.irfft(spec, n)
            x -= x.mean()  # removes the rounding-level residue of the zeroed DC bin
            x *= math.sqrt(target / float(np.mean(x * x)))
            out.append(np.ascontiguousarray(x))
        t = np.arange(n, dtype=np.float64) / self.sample_rate_hz
        return t, out[0], out[1], out[2]
