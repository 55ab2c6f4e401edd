"""Tests for sitl.world.wind (SI units, NED world frame, wind = air-mass velocity in NED)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from scipy import signal

from sitl.world.wind import (
    KaimalTurbulence,
    SteadyWind,
    WindChange,
    WindField,
    kaimal_psd,
    velocity_from_speed_direction,
    wind_velocity,
)

SIGMA_U = 1.5
MEAN_SPEED = 10.0
RATE = 50.0


@pytest.fixture(scope="module")
def long_field() -> WindField:
    """10 m/s from the north, sigma_u = 1.5 m/s at 10 m, 16384 s at 50 Hz (~0.1 s to build)."""
    turb = KaimalTurbulence(SIGMA_U, height_m=10.0, duration_s=16384.0, sample_rate_hz=RATE)
    return WindField(SteadyWind(velocity_from_speed_direction(MEAN_SPEED, 0.0)), turb, seed=7)


def test_welch_psd_matches_kaimal_in_octave_bands(long_field: WindField) -> None:
    assert long_field.turbulence_series is not None
    _, *comps = long_field.turbulence_series
    turb = long_field.turbulence
    assert turb is not None
    edges = 0.01 * 2.0 ** np.arange(11)  # 0.01 .. 10.24 Hz
    edges[-1] = 10.0
    for comp, sigma, length in zip(comps, turb.sigmas(), turb.length_scales(), strict=True):
        f, pxx = signal.welch(comp, fs=RATE, nperseg=8192)  # df = 0.0061 Hz
        target = kaimal_psd(f, sigma, length, MEAN_SPEED)
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            band = (f >= lo) & (f < hi)
            assert band.sum() >= 1
            ratio = pxx[band].mean() / target[band].mean()
            assert abs(ratio - 1.0) < 0.2, (sigma, lo, hi, ratio)


def test_standard_deviations_and_zero_mean(long_field: WindField) -> None:
    assert long_field.turbulence_series is not None and long_field.turbulence is not None
    _, u, v, w = long_field.turbulence_series
    sigmas = long_field.turbulence.sigmas()
    assert sigmas == pytest.approx((1.5, 1.2, 0.75))
    resolved = long_field.turbulence.resolved_variances(MEAN_SPEED)
    for comp, sigma, var in zip((u, v, w), sigmas, resolved, strict=True):
        assert abs(comp.mean()) < 1e-12
        # The series is scaled to the resolved-band integral exactly...
        assert np.var(comp) == pytest.approx(var, rel=1e-9)
        # ...which is within 5 % of the full sigma (50 Hz resolves almost all of it).
        assert abs(np.std(comp) / sigma - 1.0) < 0.05
    # Independent components.
    assert abs(np.corrcoef(u, v)[0, 1]) < 0.05
    assert abs(np.corrcoef(u, w)[0, 1]) < 0.05


def _short_field(seed: int | np.random.SeedSequence, taylor: bool = True) -> WindField:
    turb = KaimalTurbulence(1.0, duration_s=120.0, sample_rate_hz=20.0, taylor=taylor)
    return WindField(SteadyWind((3.0, 4.0, 0.0)), turb, seed)


def test_seed_reproducibility() -> None:
    a = _short_field(3).turbulence_series
    b = _short_field(3).turbulence_series
    c = _short_field(4).turbulence_series
    d = _short_field(np.random.SeedSequence(3)).turbulence_series
    assert a is not None and b is not None and c is not None and d is not None
    for x, y, s in zip(a, b, d, strict=True):
        assert np.array_equal(x, y)
        assert np.array_equal(x, s)  # an int and its SeedSequence give the same stream
    for x, z in zip(a[1:], c[1:], strict=True):
        assert not np.allclose(x, z)


def test_no_turbulence_field_is_steady() -> None:
    wf = WindField(SteadyWind((1.0, -2.0, 0.5)), None, seed=0)
    assert wf.turbulence_series is None
    k = wf.kernel()
    assert k.turb_on is False and k.turb_uvw.shape == (0, 3)
    assert np.array_equal(wf.velocity(5.0, np.array([3.0, 1.0, -7.0])), [1.0, -2.0, 0.5])


def test_step_change_at_23_s() -> None:
    sw = SteadyWind((2.0, 0.0, 0.0), changes=(WindChange(23.0, (0.0, 5.0, 0.0)),))
    wf = WindField(sw, None, seed=0)
    p = np.zeros(3)
    assert np.array_equal(wf.mean(0.0, p), [2.0, 0.0, 0.0])
    assert np.array_equal(wf.mean(22.999, p), [2.0, 0.0, 0.0])
    assert np.array_equal(wf.mean(23.0, p), [0.0, 5.0, 0.0])
    assert np.array_equal(wf.velocity(100.0, p), [0.0, 5.0, 0.0])


def test_direction_every_10_s_and_unsorted_changes() -> None:
    sw = SteadyWind.direction_steps(4.0, [0.0, 90.0, 180.0, 270.0], interval_s=10.0)
    wf = WindField(sw, None, seed=0)
    p = np.zeros(3)
    expected = [(-4, 0), (0, -4), (4, 0), (0, 4)]
    for k, (vn, ve) in enumerate(expected):
        for t in (10.0 * k, 10.0 * k + 9.99):
            assert wf.mean(t, p)[:2] == pytest.approx((vn, ve), abs=1e-12)
    # Changes given out of order are sorted; the schedule then behaves the same.
    shuffled = SteadyWind(sw.velocity_ned, changes=tuple(reversed(sw.changes)))
    assert shuffled.changes == sw.changes


def test_speed_direction_conversion() -> None:
    assert velocity_from_speed_direction(10.0, 0.0) == pytest.approx((-10.0, 0.0, 0.0))
    assert velocity_from_speed_direction(10.0, 90.0) == pytest.approx((0.0, -10.0, 0.0))
    n, e, d = velocity_from_speed_direction(10.0, 45.0, vertical_ms=0.5)
    assert n < 0 and e < 0 and n == pytest.approx(e) and d == 0.5
    assert math.hypot(n, e) == pytest.approx(10.0)
    assert SteadyWind.from_speed_direction(10.0, 0.0).velocity_ned == pytest.approx((-10, 0, 0))


def test_log_profile() -> None:
    sw = SteadyWind((7.0, 0.0, 0.3), profile="log", reference_height_m=10.0)
    wf = WindField(sw, None, seed=0)
    at_ref = wf.mean(0.0, np.array([0.0, 0.0, -10.0]))
    below = wf.mean(0.0, np.array([0.0, 0.0, -2.0]))
    above = wf.mean(0.0, np.array([0.0, 0.0, -50.0]))
    assert at_ref == pytest.approx([7.0, 0.0, 0.3])
    assert 0.0 < below[0] < 7.0 and above[0] > 7.0
    assert below[0] == pytest.approx(7.0 * math.log(2.0 / 0.1) / math.log(10.0 / 0.1))
    assert below[2] == above[2] == 0.3  # vertical not scaled
    for z in (-0.1, -0.05, 0.0, 1.0):  # at/below z0 and underground
        v = wf.mean(0.0, np.array([0.0, 0.0, z]))
        assert np.all(np.isfinite(v)) and v[0] == 0.0 and v[2] == 0.3
    # Uniform profile: the same everywhere.
    uni = WindField(SteadyWind((7.0, 0.0, 0.0)), None, seed=0)
    assert np.array_equal(uni.mean(0.0, np.array([0.0, 0.0, -2.0])), [7.0, 0.0, 0.0])


def test_taylor_frozen_turbulence() -> None:
    wf = _short_field(11, taylor=True)
    mean = np.array([3.0, 4.0, 0.0])
    e = mean / 5.0
    origin = np.array([0.0, 0.0, -10.0])
    for t, dt in ((1.0, 0.37), (50.0, 2.0), (119.0, 3.5)):  # the last wraps the period
        downstream = origin + e * 5.0 * dt
        assert wf.velocity(t + dt, downstream) == pytest.approx(wf.velocity(t, origin), abs=1e-9)
        # A crosswind offset does not shift the sampled time.
        cross = origin + 7.0 * np.array([-e[1], e[0], 0.0])
        assert wf.velocity(t, cross) == pytest.approx(wf.velocity(t, origin), abs=1e-12)
    # And turbulence really is there (the test above would pass for a steady field).
    samples = wf.velocity(0.0, np.column_stack([np.arange(200.0), np.zeros(200), np.zeros(200)]))
    assert np.std(samples[:, 0]) > 0.2


def test_turbulence_rotated_into_mean_wind_axes() -> None:
    wf = _short_field(5, taylor=False)
    assert wf.turbulence_series is not None
    t, u, v, w = wf.turbulence_series
    e = np.array([0.6, 0.8])
    perp = np.array([-0.8, 0.6])  # e rotated +90 deg
    k = 37
    got = wf.velocity(t[k], np.array([123.0, -45.0, -3.0]))  # no Taylor: position-independent
    expected_h = np.array([3.0, 4.0]) + u[k] * e + v[k] * perp
    assert got == pytest.approx([expected_h[0], expected_h[1], w[k]], abs=1e-12)
    # Linear interpolation halfway between samples, and periodic wrap at the end.
    half = wf.velocity(t[k] + 0.025, np.zeros(3))
    assert half[2] == pytest.approx(0.5 * (w[k] + w[k + 1]), abs=1e-12)
    period = len(t) / 20.0
    assert wf.velocity(t[k] + 3 * period, np.zeros(3)) == pytest.approx(got, abs=1e-9)
    assert wf.velocity(t[k] - period, np.zeros(3)) == pytest.approx(got, abs=1e-9)


def test_many_points_equal_single_calls() -> None:
    wf = _short_field(2)
    pts = np.random.default_rng(0).uniform(-100.0, 100.0, size=(64, 3))
    many = wf.velocity(12.3, pts)
    assert many.shape == (64, 3)
    single = np.array([wf.velocity(12.3, p) for p in pts])
    assert np.array_equal(many, single)
    with pytest.raises(ValueError, match="pos_ned"):
        wf.velocity(0.0, np.zeros((2, 2)))


def test_kernel_callable_from_user_njit() -> None:
    wf = _short_field(2)

    @njit
    def sample(t: float, pos: np.ndarray, w: object) -> np.ndarray:
        return wind_velocity(t, pos, w)

    p = np.array([1.0, 2.0, -3.0])
    assert np.array_equal(sample(4.0, p, wf.kernel()), wf.velocity(4.0, p))


def test_intensity_helpers() -> None:
    k = KaimalTurbulence.from_intensity_class("B", 10.0)
    assert k.sigma_u == pytest.approx(0.14 * (0.75 * 10.0 + 5.6))
    assert KaimalTurbulence.from_intensity_class("a", 8.0).sigma_u == pytest.approx(0.16 * 11.6)
    assert KaimalTurbulence.from_intensity(0.2, 5.0).sigma_u == pytest.approx(1.0)
    assert KaimalTurbulence(1.0, height_m=100.0).length_scales() == pytest.approx(
        (8.1 * 42, 2.7 * 42, 0.66 * 42)
    )
    # Calm air: U is floored at 1 m/s, the spectrum stays finite.
    assert np.all(np.isfinite(kaimal_psd(np.array([0.0, 1.0]), 1.0, 10.0, 0.0)))


@pytest.mark.parametrize(
    ("make", "field_name"),
    [
        (lambda: SteadyWind((1.0, float("nan"), 0.0)), "velocity_ned"),
        (lambda: SteadyWind((1.0, 0.0)), "velocity_ned"),
        (lambda: SteadyWind((1.0, 0.0, 0.0), profile="power"), "profile"),
        (lambda: SteadyWind((1.0, 0.0, 0.0), reference_height_m=0.0), "reference_height_m"),
        (lambda: SteadyWind((1.0, 0.0, 0.0), roughness_length_m=20.0), "roughness_length_m"),
        (
            lambda: SteadyWind(
                (1.0, 0.0, 0.0), changes=(WindChange(5.0, (0, 0, 0)), WindChange(5.0, (1, 0, 0)))
            ),
            "t_s",
        ),
        (lambda: WindChange(float("inf"), (0.0, 0.0, 0.0)), "t_s"),
        (lambda: KaimalTurbulence(-1.0), "sigma_u"),
        (lambda: KaimalTurbulence(1.0, sample_rate_hz=0.0), "sample_rate_hz"),
        (lambda: KaimalTurbulence(1.0, duration_s=-5.0), "duration_s"),
        (lambda: KaimalTurbulence(1.0, height_m=float("nan")), "height_m"),
        (lambda: KaimalTurbulence.from_intensity_class("D", 10.0), "cls_letter"),
        (lambda: KaimalTurbulence.from_intensity(-0.1, 10.0), "ti"),
        (lambda: velocity_from_speed_direction(-1.0, 0.0), "speed_ms"),
    ],
)
def test_validation_names_the_field(make: object, field_name: str) -> None:
    with pytest.raises(ValueError, match=field_name):
        make()  # type: ignore[operator]
