"""The orthogonal phase-optimized multisine (identify.multisine): orthogonality, peaks, band, peak
factors, zero start and end, reproducibility, evaluation at other rates."""

from __future__ import annotations

import numpy as np
import pytest

from identify.multisine import Multisine, design_multisine, relative_peak_factor


@pytest.fixture(scope="module")
def paper_design() -> Multisine:
    """The paper's excitation: 4 virtual actuators, 2 minutes, 0.1-2 Hz, sampled at 100 Hz."""
    return design_multisine(4, 120.0, 0.01, 0.1, 2.0)


def test_inputs_are_mutually_orthogonal(paper_design: Multisine) -> None:
    u = paper_design.u
    corr = np.corrcoef(u.T)
    assert np.max(np.abs(corr - np.eye(4))) < 1e-6
    assert np.max(np.abs(u.mean(axis=0))) < 1e-9  # no mean: the band holds no zero frequency


def test_relative_peak_factor_is_low(paper_design: Multisine) -> None:
    rpf = paper_design.relative_peak_factor
    print(f"relative peak factors, 4 inputs, 120 s, 0.1-2 Hz: {np.round(rpf, 3)}")
    assert np.all(rpf < 1.2)
    for j in range(4):
        assert rpf[j] == pytest.approx(relative_peak_factor(paper_design.u[:-1, j]))


def test_band_and_interleaving(paper_design: Multisine) -> None:
    T = paper_design.duration_s
    allk = np.sort(np.concatenate([np.round(f * T) for f in paper_design.frequencies_hz]))
    np.testing.assert_array_equal(allk, np.arange(12, 241))  # every harmonic of 1/T in the band, once
    for j, f in enumerate(paper_design.frequencies_hz):
        assert np.all((f >= 0.1 - 1e-12) & (f <= 2.0 + 1e-12))
        np.testing.assert_allclose(np.diff(f), 4.0 / T)  # every 4th harmonic: interleaved
        assert f[0] == pytest.approx((12 + j) / T)
        amp = paper_design.component_amplitudes[j]
        np.testing.assert_allclose(amp, amp[0])  # equal power per component


def test_spectrum_holds_only_the_inputs_own_harmonics(paper_design: Multisine) -> None:
    T, n = paper_design.duration_s, paper_design.t.size - 1
    for j, f in enumerate(paper_design.frequencies_hz):
        spectrum = np.abs(np.fft.rfft(paper_design.u[:-1, j])) * 2.0 / n
        own = np.round(f * T).astype(int)
        np.testing.assert_allclose(spectrum[own], paper_design.component_amplitudes[j], rtol=1e-9)
        others = np.delete(spectrum, own)
        assert np.max(others) < 1e-9 * np.max(spectrum)


def test_starts_and_ends_at_zero_and_peaks_are_the_amplitudes() -> None:
    peaks = [1.0, 0.5, 2.0, 0.1]
    sig = design_multisine(4, 30.0, 0.02, 0.2, 3.0, amplitudes=peaks)
    assert sig.u.shape == (1501, 4)
    assert sig.t[0] == 0.0 and sig.t[-1] == pytest.approx(30.0)
    np.testing.assert_allclose(np.max(np.abs(sig.u), axis=0), peaks, rtol=1e-12)
    assert np.all(np.abs(sig.u[0]) < 1e-9 * np.asarray(peaks))
    assert np.all(np.abs(sig.u[-1]) < 1e-9 * np.asarray(peaks))
    assert np.max(np.abs(np.corrcoef(sig.u.T) - np.eye(4))) < 1e-6


def test_at_matches_the_samples_and_is_periodic(paper_design: Multisine) -> None:
    np.testing.assert_allclose(paper_design.at(paper_design.t[::97]), paper_design.u[::97], atol=1e-12)
    assert paper_design.at(3.21).shape == (4,)
    np.testing.assert_allclose(paper_design.at(3.21), paper_design.at(3.21 + 120.0), atol=1e-9)
    fine = paper_design.at(np.arange(0.0, 120.0, 0.002))  # a 500 Hz controller
    overshoot = np.max(np.abs(fine), axis=0)
    print(f"peak between the 100 Hz samples, sampled at 500 Hz: {np.round(overshoot, 5)}")
    assert np.all(overshoot < 1.005)


def test_reproducible_for_a_seed() -> None:
    a = design_multisine(2, 20.0, 0.05, 0.1, 2.0, seed=3)
    b = design_multisine(2, 20.0, 0.05, 0.1, 2.0, seed=3)
    c = design_multisine(2, 20.0, 0.05, 0.1, 2.0, seed=4)
    np.testing.assert_array_equal(a.u, b.u)
    for pa, pb in zip(a.phases_rad, b.phases_rad, strict=True):
        np.testing.assert_array_equal(pa, pb)
    assert not np.array_equal(a.u, c.u)
    assert not a.u.flags.writeable


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((4, 10.0, 0.01, 0.1, 0.3), "fewer than the 4 inputs"),
        ((2, 10.0, 0.1, 0.1, 5.0), "Nyquist"),
        ((2, 10.0, 0.03, 0.1, 2.0), "integer"),
        ((2, 10.0, 0.01, 2.0, 1.0), "f_min_hz < f_max_hz"),
        ((0, 10.0, 0.01, 0.1, 2.0), "n_inputs"),
    ],
)
def test_bad_arguments_are_refused(args: tuple[int, float, float, float, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        design_multisine(*args)


def test_amplitudes_need_one_positive_value_per_input() -> None:
    with pytest.raises(ValueError, match="one peak amplitude per input"):
        design_multisine(2, 10.0, 0.01, 0.1, 2.0, amplitudes=[1.0])
    with pytest.raises(ValueError, match="positive"):
        design_multisine(2, 10.0, 0.01, 0.1, 2.0, amplitudes=[1.0, -1.0])
