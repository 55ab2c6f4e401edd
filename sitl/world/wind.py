"""Wind model: steady wind with a time schedule and height profile, plus Kaimal turbulence.

Conventions (shared with the rest of ``sitl``):

- SI units throughout (m, s, m/s, Hz; spectra in (m/s)^2/Hz).
- World frame NED: x north, y east, z down; the ground is at z = 0, so altitude = -z.
- Body frame FRD (not used here: every wind quantity is in NED).
- Wind is the *air-mass velocity* in NED, i.e. the velocity the air moves with.
  A 10 m/s wind *from* the north blows toward the south: ``[-10, 0, 0]`` m/s.
- Directions are meteorological from-directions in degrees: 0 = from north, 90 = from east.
  A wind from direction d blows toward d + 180 deg.
- Every random process is seeded (``np.random.Generator`` built from an int or a
  ``np.random.SeedSequence``); the same seed gives bit-identical output.

Structure:

- :class:`SteadyWind` describes the mean wind: an initial air-mass velocity at the reference
  height, piecewise-constant step changes (:class:`WindChange`), and a ``"uniform"`` or
  ``"log"`` height profile.
- :class:`KaimalTurbulence` describes IEC 61400-1 Kaimal turbulence; the three components
  (u' along the mean wind, v' crosswind, w' vertical) are synthesized once as periodic time
  series by the exact non-causal (spectral) method.
- :class:`WindField` binds both and a seed. Sampling is done by the numba kernels
  :func:`wind_mean`, :func:`wind_velocity` and :func:`wind_velocity_many`, which are the
  single implementation; the Python methods only call them. The simulator calls
  ``wind_velocity(t, pos, *field.kernel_args())`` from its own njit code.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy import fft as sfft

Vec3 = tuple[float, float, float]

# IEC 61400-1 reference turbulence intensities (at 15 m/s) per turbine class letter.
IEC_I_REF: dict[str, float] = {"A": 0.16, "B": 0.14, "C": 0.12}

# The Kaimal spectrum uses L/U; a floor keeps it finite in calm air.
MIN_ADVECTION_SPEED_MS = 1.0

_PROFILES = ("uniform", "log")


# ---------------------------------------------------------------------------------------------
# Validation helpers
# ---------------------------------------------------------------------------------------------


def _as_vec3(value: Iterable[float], name: str) -> Vec3:
    """Return ``value`` as a tuple of three finite floats, or raise ``ValueError`` naming it."""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be 3 finite numbers (m/s, NED), got {value!r}") from exc
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers (m/s, NED), got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _check_finite(value: float, name: str, allowed: str, ok: bool) -> float:
    """Raise ``ValueError`` naming ``name`` and its ``allowed`` range unless finite and ``ok``."""
    v = float(value)
    if not math.isfinite(v) or not ok:
        raise ValueError(f"{name} must be {allowed}, got {value!r}")
    return v


def velocity_from_speed_direction(
    speed_ms: float, from_deg: float, vertical_ms: float = 0.0
) -> Vec3:
    """Air-mass velocity (NED, m/s) of a wind of ``speed_ms`` blowing *from* ``from_deg``.

    ``from_deg`` is meteorological: 0 = from north, 90 = from east; the air moves toward
    ``from_deg + 180``. ``vertical_ms`` is the NED z (down) component of the air velocity, so a
    positive value is a downdraft. Example: 10 m/s from north -> ``(-10, 0, 0)``.
    """
    speed = _check_finite(speed_ms, "speed_ms", "a finite number >= 0 (m/s)", speed_ms >= 0)
    d = _check_finite(from_deg, "from_deg", "a finite angle in degrees", True)
    vz = _check_finite(vertical_ms, "vertical_ms", "a finite number (m/s, NED down)", True)
    rad = math.radians(d)
    return (-speed * math.cos(rad), -speed * math.sin(rad), vz)


# ---------------------------------------------------------------------------------------------
# Steady wind
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class WindChange:
    """A step change of the mean wind: from time ``t_s`` (s) on, the air-mass velocity at the
    reference height is ``velocity_ned`` (m/s, NED)."""

    t_s: float
    velocity_ned: Vec3

    def __post_init__(self) -> None:
        t = _check_finite(self.t_s, "WindChange.t_s", "a finite time in s", True)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(
            self, "velocity_ned", _as_vec3(self.velocity_ned, "WindChange.velocity_ned")
        )


@dataclass(frozen=True)
class SteadyWind:
    """Mean (non-turbulent) wind.

    Attributes:
        velocity_ned: air-mass velocity at ``reference_height_m`` before the first change
            (m/s, NED).
        changes: step changes; sorted by time on construction, times must be finite and
            strictly increasing. The mean at time t is the last change with ``t_s <= t``,
            else ``velocity_ned``.
        profile: ``"uniform"`` (no height dependence) or ``"log"`` (horizontal components
            scaled by ``ln(max(h, z0)/z0) / ln(z_ref/z0)`` with h = -z the altitude above
            ground; the vertical component is not scaled, and the wind is 0 at/below z0).
        reference_height_m: z_ref, the height at which the velocities are given (m, > 0).
        roughness_length_m: z0 of the log profile (m, 0 < z0 < z_ref).
    """

    velocity_ned: Vec3
    changes: tuple[WindChange, ...] = ()
    profile: str = "uniform"
    reference_height_m: float = 10.0
    roughness_length_m: float = 0.1

    def __post_init__(self) -> None:
        object.__setattr__(self, "velocity_ned", _as_vec3(self.velocity_ned, "velocity_ned"))
        changes = []
        for c in self.changes:
            if isinstance(c, WindChange):
                changes.append(c)
            else:
                try:
                    t_s, vel = c
                except (TypeError, ValueError) as exc:
                    raise ValueError(
                        f"changes must hold WindChange or (t_s, velocity_ned) pairs, got {c!r}"
                    ) from exc
                changes.append(WindChange(t_s, vel))
        changes.sort(key=lambda c: c.t_s)
        for a, b in zip(changes, changes[1:], strict=False):
            if not b.t_s > a.t_s:
                raise ValueError(
                    f"changes must have strictly increasing t_s (s), got {a.t_s} twice"
                )
        object.__setattr__(self, "changes", tuple(changes))
        if self.profile not in _PROFILES:
            raise ValueError(f"profile must be one of {_PROFILES}, got {self.profile!r}")
        z_ref = _check_finite(
            self.reference_height_m,
            "reference_height_m",
            "a finite height > 0 (m)",
            self.reference_height_m > 0,
        )
        z0 = _check_finite(
            self.roughness_length_m,
            "roughness_length_m",
            f"a finite length with 0 < z0 < reference_height_m = {z_ref} (m)",
            0 < self.roughness_length_m < z_ref,
        )
        object.__setattr__(self, "reference_height_m", z_ref)
        object.__setattr__(self, "roughness_length_m", z0)

    velocity_from_speed_direction = staticmethod(velocity_from_speed_direction)

    @classmethod
    def from_speed_direction(
        cls, speed_ms: float, from_deg: float, vertical_ms: float = 0.0, **kwargs: object
    ) -> SteadyWind:
        """Constant wind of ``speed_ms`` (m/s) from ``from_deg`` (deg); kwargs go to the class."""
        return cls(velocity_from_speed_direction(speed_ms, from_deg, vertical_ms), **kwargs)

    @classmethod
    def direction_steps(
        cls,
        speed_ms: float,
        from_degs: Sequence[float],
        interval_s: float,
        **kwargs: object,
    ) -> SteadyWind:
        """Constant speed, new from-direction every ``interval_s`` s (anemotaxis scenarios).

        ``from_degs[0]`` holds on [0, interval_s), ``from_degs[k]`` from ``k * interval_s`` on.
        """
        if len(from_degs) == 0:
            raise ValueError("from_degs must hold at least one direction (deg)")
        step = _check_finite(interval_s, "interval_s", "a finite time > 0 (s)", interval_s > 0)
        vels = [velocity_from_speed_direction(speed_ms, d) for d in from_degs]
        changes = tuple(WindChange(k * step, v) for k, v in enumerate(vels) if k > 0)
        return cls(vels[0], changes=changes, **kwargs)

    def schedule_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Schedule as kernel arrays: times (K+1,) with a leading -inf, velocities (K+1, 3)."""
        times = np.array([-np.inf] + [c.t_s for c in self.changes], dtype=np.float64)
        vels = np.array(
            [self.velocity_ned] + [c.velocity_ned for c in self.changes], dtype=np.float64
        )
        return times, np.ascontiguousarray(vels)


# ---------------------------------------------------------------------------------------------
# Kaimal turbulence
# ---------------------------------------------------------------------------------------------


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
        _check_finite(self.sigma_u, "sigma_u", "a finite number >= 0 (m/s)", self.sigma_u >= 0)
        _check_finite(self.height_m, "height_m", "a finite height > 0 (m)", self.height_m > 0)
        _check_finite(
            self.duration_s, "duration_s", "a finite duration > 0 (s)", self.duration_s > 0
        )
        _check_finite(
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
            _check_finite(
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
        u = _check_finite(mean_speed, "mean_speed", "a finite speed >= 0 (m/s)", mean_speed >= 0)
        kwargs.setdefault("mean_speed_ms", u)
        return cls(sigma_u=IEC_I_REF[letter] * (0.75 * u + 5.6), **kwargs)  # type: ignore[arg-type]

    @classmethod
    def from_intensity(cls, ti: float, mean_speed: float, **kwargs: object) -> KaimalTurbulence:
        """sigma_u = ti * U for a turbulence intensity ``ti`` (>= 0) and U = ``mean_speed`` m/s."""
        i = _check_finite(ti, "ti", "a finite intensity >= 0", ti >= 0)
        u = _check_finite(mean_speed, "mean_speed", "a finite speed >= 0 (m/s)", mean_speed >= 0)
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


# ---------------------------------------------------------------------------------------------
# Numba kernels: the single implementation of wind sampling
# ---------------------------------------------------------------------------------------------
#
# Kernel argument order (what WindField.kernel_args() returns):
#   sched_t      float64 (K+1,)   change times (s), sched_t[0] = -inf (initial wind)
#   sched_vel    float64 (K+1,3)  air-mass velocity at the reference height (m/s, NED)
#   log_profile  bool             True: log height profile, False: uniform
#   z0           float            roughness length (m)
#   inv_log_ref  float            1 / ln(z_ref / z0)
#   turb_on      bool             False: no turbulence (turb_uvw is then (0,3))
#   taylor       bool             frozen-turbulence sampling
#   turb_rate    float            sample rate of the series (Hz)
#   turb_uvw     float64 (M,3)    u', v', w' series (m/s), periodic


@njit(cache=True)
def _schedule_index(t: float, sched_t: np.ndarray) -> int:
    """Index of the last schedule entry with time <= t (binary search; entry 0 is -inf)."""
    lo = 0
    hi = sched_t.shape[0] - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if sched_t[mid] <= t:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(cache=True)
def _mean_components(
    t: float,
    z: float,
    sched_t: np.ndarray,
    sched_vel: np.ndarray,
    log_profile: bool,
    z0: float,
    inv_log_ref: float,
) -> tuple[float, float, float, float, float]:
    """(mean n, e, d at height -z; reference-height n, e) in m/s NED at time t."""
    i = _schedule_index(t, sched_t)
    vn = sched_vel[i, 0]
    ve = sched_vel[i, 1]
    vd = sched_vel[i, 2]
    scale = 1.0
    if log_profile:
        h = -z
        # max() with z0 makes the wind vanish smoothly at/below z0 instead of log(0) = -inf.
        scale = math.log(max(h, z0) / z0) * inv_log_ref
    return vn * scale, ve * scale, vd, vn, ve


@njit(cache=True)
def _wind_components(
    t: float,
    x: float,
    y: float,
    z: float,
    sched_t: np.ndarray,
    sched_vel: np.ndarray,
    log_profile: bool,
    z0: float,
    inv_log_ref: float,
    turb_on: bool,
    taylor: bool,
    turb_rate: float,
    turb_uvw: np.ndarray,
) -> tuple[float, float, float]:
    """Air-mass velocity (m/s, NED) at NED point (x, y, z) and time t, as three floats."""
    mn, me, md, rn, re = _mean_components(t, z, sched_t, sched_vel, log_profile, z0, inv_log_ref)
    if not turb_on:
        return mn, me, md
    # The frozen field is advected by the reference-height mean wind, one speed for all
    # heights, so that the turbulence stays a single field even under a log profile.
    speed = math.sqrt(rn * rn + re * re)
    if speed > 1e-9:
        en = rn / speed
        ee = re / speed
    else:
        en = 1.0  # calm: any axis works, north keeps the output defined
        ee = 0.0
    u_adv = max(speed, 1.0)
    tau = t
    if taylor:
        tau = t - (x * en + y * ee) / u_adv
    m = turb_uvw.shape[0]
    s = tau * turb_rate
    s -= m * math.floor(s / m)  # periodic series: wrap into [0, m)
    i = int(s)
    if i >= m:  # s can round up to exactly m
        i = 0
    frac = s - i
    j = i + 1
    if j == m:
        j = 0
    up = turb_uvw[i, 0] + frac * (turb_uvw[j, 0] - turb_uvw[i, 0])
    vp = turb_uvw[i, 1] + frac * (turb_uvw[j, 1] - turb_uvw[i, 1])
    wp = turb_uvw[i, 2] + frac * (turb_uvw[j, 2] - turb_uvw[i, 2])
    # u' along e, v' along e rotated +90 deg about down, w' along NED down.
    return mn + up * en - vp * ee, me + up * ee + vp * en, md + wp


@njit(cache=True)
def wind_mean(
    t: float,
    pos: np.ndarray,
    sched_t: np.ndarray,
    sched_vel: np.ndarray,
    log_profile: bool,
    z0: float,
    inv_log_ref: float,
    turb_on: bool,
    taylor: bool,
    turb_rate: float,
    turb_uvw: np.ndarray,
) -> np.ndarray:
    """Steady air-mass velocity (3,) m/s NED at NED ``pos`` (3,) m and time ``t`` s.

    Takes the full kernel argument list (turbulence arguments ignored) so callers can pass
    ``*field.kernel_args()`` as for :func:`wind_velocity`.
    """
    mn, me, md, _, _ = _mean_components(t, pos[2], sched_t, sched_vel, log_profile, z0, inv_log_ref)
    out = np.empty(3)
    out[0] = mn
    out[1] = me
    out[2] = md
    return out


@njit(cache=True)
def wind_velocity(
    t: float,
    pos: np.ndarray,
    sched_t: np.ndarray,
    sched_vel: np.ndarray,
    log_profile: bool,
    z0: float,
    inv_log_ref: float,
    turb_on: bool,
    taylor: bool,
    turb_rate: float,
    turb_uvw: np.ndarray,
) -> np.ndarray:
    """Air-mass velocity (3,) m/s NED (mean + turbulence) at NED ``pos`` (3,) m, time ``t`` s."""
    vn, ve, vd = _wind_components(
        t,
        pos[0],
        pos[1],
        pos[2],
        sched_t,
        sched_vel,
        log_profile,
        z0,
        inv_log_ref,
        turb_on,
        taylor,
        turb_rate,
        turb_uvw,
    )
    out = np.empty(3)
    out[0] = vn
    out[1] = ve
    out[2] = vd
    return out


@njit(cache=True)
def wind_velocity_many(
    t: float,
    pos_many: np.ndarray,
    sched_t: np.ndarray,
    sched_vel: np.ndarray,
    log_profile: bool,
    z0: float,
    inv_log_ref: float,
    turb_on: bool,
    taylor: bool,
    turb_rate: float,
    turb_uvw: np.ndarray,
) -> np.ndarray:
    """Air-mass velocities (N,3) m/s NED at NED points ``pos_many`` (N,3) m, time ``t`` s."""
    n = pos_many.shape[0]
    out = np.empty((n, 3))
    for k in range(n):
        vn, ve, vd = _wind_components(
            t,
            pos_many[k, 0],
            pos_many[k, 1],
            pos_many[k, 2],
            sched_t,
            sched_vel,
            log_profile,
            z0,
            inv_log_ref,
            turb_on,
            taylor,
            turb_rate,
            turb_uvw,
        )
        out[k, 0] = vn
        out[k, 1] = ve
        out[k, 2] = vd
    return out


# ---------------------------------------------------------------------------------------------
# WindField
# ---------------------------------------------------------------------------------------------


@dataclass(eq=False)
class WindField:
    """Steady wind + optional Kaimal turbulence, seeded; what the simulator and plume sample.

    Args:
        steady: mean wind, schedule and profile.
        turbulence: Kaimal turbulence or None for a steady field.
        seed: int or ``np.random.SeedSequence`` for the turbulence noise.

    The turbulence spectra use U = ``turbulence.mean_speed_ms`` if given, else the horizontal
    speed of ``steady.velocity_ned`` (the initial wind at the reference height).
    """

    steady: SteadyWind
    turbulence: KaimalTurbulence | None
    seed: int | np.random.SeedSequence
    turbulence_series: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = field(
        init=False, default=None
    )
    turbulence_mean_speed_ms: float = field(init=False, default=0.0)
    _args: tuple = field(init=False, repr=False, default=())

    def __post_init__(self) -> None:
        sched_t, sched_vel = self.steady.schedule_arrays()
        z0 = self.steady.roughness_length_m
        inv_log_ref = 1.0 / math.log(self.steady.reference_height_m / z0)
        turb = self.turbulence
        if turb is None:
            uvw = np.zeros((0, 3), dtype=np.float64)
            turb_on, taylor, rate = False, False, 1.0
        else:
            if turb.mean_speed_ms is not None:
                u_mean = turb.mean_speed_ms
            else:
                u_mean = math.hypot(self.steady.velocity_ned[0], self.steady.velocity_ned[1])
            self.turbulence_mean_speed_ms = float(u_mean)
            rng = np.random.default_rng(self.seed)
            series = turb.synthesize(u_mean, rng)
            self.turbulence_series = series
            uvw = np.ascontiguousarray(np.stack(series[1:], axis=1))
            turb_on, taylor, rate = True, turb.taylor, float(turb.sample_rate_hz)
        self._args = (
            sched_t,
            sched_vel,
            self.steady.profile == "log",
            float(z0),
            float(inv_log_ref),
            turb_on,
            taylor,
            rate,
            uvw,
        )

    def kernel_args(self) -> tuple:
        """Arguments after (t, pos) of the njit kernels, in the documented order:
        (sched_t, sched_vel, log_profile, z0, inv_log_ref, turb_on, taylor, turb_rate, turb_uvw).
        """
        return self._args

    def mean(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Steady air-mass velocity (3,) m/s NED at NED point ``pos_ned`` (3,) m, time t s."""
        pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
        if pos.shape != (3,):
            raise ValueError(f"pos_ned must have shape (3,) (m, NED), got {pos.shape}")
        return wind_mean(float(t), pos, *self._args)

    def velocity(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Air-mass velocity (mean + turbulence), m/s NED, at NED point(s) ``pos_ned`` (m).

        ``pos_ned`` of shape (3,) gives (3,); shape (N, 3) gives (N, 3).
        """
        pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
        if pos.shape == (3,):
            return wind_velocity(float(t), pos, *self._args)
        if pos.ndim == 2 and pos.shape[1] == 3:
            return wind_velocity_many(float(t), pos, *self._args)
        raise ValueError(f"pos_ned must have shape (3,) or (N, 3) (m, NED), got {pos.shape}")
