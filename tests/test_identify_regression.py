"""Equation-error least squares, step-wise regression and the fit metrics (identify.regression,
identify.stepwise, identify.metrics): exact recovery, selection and interval coverage with white noise,
partial F against statsmodels' nested F test, coloured-residual coverage, degenerate regressors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import statsmodels.api as sm
from scipy.signal import lfilter

from identify.metrics import nrmse, r_squared, s_squared, tic
from identify.regression import coloured_max_lag, fit
from identify.stepwise import prune_insignificant, stepwise

#: The true model: 6 of the 12 candidates of ``_candidates``, in the style of the paper's Eq. 46a.
TRUE = {"bias": -2.0, "w": -2.0, "dt": -2.5e-5, "u_cbrt_dt": -0.015, "u_abs_u": -0.1, "p_sqrt_dt": -4e-3}


def _smooth(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    """A smooth zero-mean signal (AR(1) with coefficient ``phi``), peak 1."""
    x = lfilter([1.0], [1.0, -phi], rng.standard_normal(n + 500))[500:]
    return x / np.max(np.abs(x))


def _ar1(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    """AR(1) noise with unit innovations, started in its stationary state."""
    e = rng.standard_normal(n)
    e[0] /= math.sqrt(1.0 - phi**2)
    return lfilter([1.0], [1.0, -phi], e)


def _candidates(rng: np.random.Generator, n: int = 2000) -> tuple[np.ndarray, list[str]]:
    """12 candidate regressors with flight-like scales: velocities (m/s), a rate (rad/s), a thrust
    command (rad/s)^2 ~ 5e5, and products; u, u cbrt(dt) and u|u| are correlated (|r| ~ 0.9), so are
    p and p sqrt(dt), w and w cbrt(dt) (r ~ 0.99)."""
    u, v = 5.0 * _smooth(rng, n, 0.98), 5.0 * _smooth(rng, n, 0.98)
    w, p = _smooth(rng, n, 0.95), 0.4 * _smooth(rng, n, 0.9)
    dt = 5e5 + 3e5 * _smooth(rng, n, 0.9)
    cols = {
        "bias": np.ones(n),
        "u": u,
        "v": v,
        "w": w,
        "p": p,
        "dt": dt,
        "u_cbrt_dt": u * np.cbrt(dt),
        "u_abs_u": u * np.abs(u),
        "w_cbrt_dt": w * np.cbrt(dt),
        "p_sqrt_dt": p * np.sqrt(dt),
        "v_abs_v": v * np.abs(v),
        "u_w": u * w,
    }
    return np.column_stack(list(cols.values())), list(cols)


def _truth(names: tuple[str, ...] | list[str]) -> np.ndarray:
    return np.array([TRUE.get(n, 0.0) for n in names])


def test_exact_data_are_recovered_exactly() -> None:
    X, names = _candidates(np.random.default_rng(7))
    z = X @ _truth(names)
    sw = stepwise(z, X, names)
    assert set(sw.names) == set(TRUE)
    assert sw.converged and set(sw.steps[-1].included) == set(TRUE)
    # w cbrt(dt) (r = 0.99 with w) stands in for w until w enters, then goes: F of round-off against the floor
    assert [(s.action, s.name) for s in sw.steps if s.action == "remove"] == [("remove", "w_cbrt_dt")]
    np.testing.assert_allclose(sw.fit.theta, _truth(sw.names), rtol=1e-8)
    assert sw.fit.r_squared_pct == pytest.approx(100.0)
    assert sw.not_excited == () and sw.not_identifiable == ()


def test_white_noise_selection_and_interval_coverage() -> None:
    """Over 20 seeded data sets with white noise (2 % of std z): every true regressor is chosen every
    time; a null candidate enters at about the F-test level P(F(1, N) > 4) = 4.6 %; the corrected 95 %
    intervals of the correct models cover the truth about 95 % of the time."""
    runs, missed, false_entries, right, covered, total = 20, 0, 0, 0, 0, 0
    for seed in range(runs):
        rng = np.random.default_rng(100 + seed)
        X, names = _candidates(rng, 1000)
        z0 = X @ _truth(names)
        z = z0 + 0.02 * np.std(z0) * rng.standard_normal(z0.size)
        sw = stepwise(z, X, names)
        missed += len(set(TRUE) - set(sw.names))
        false_entries += len(set(sw.names) - set(TRUE))
        if set(sw.names) == set(TRUE):
            right += 1
            covered += int(np.sum(np.abs(sw.fit.theta - _truth(sw.names)) <= sw.fit.ci95_halfwidth))
            total += len(TRUE)
        strict = stepwise(z, X, names, f_enter=16.0, f_remove=16.0)
        assert set(strict.names) == set(TRUE)
    rate = false_entries / (runs * (len(names) - len(TRUE)))
    print(f"white noise: right set {right}/{runs}, false entries {rate:.1%} per null candidate, "
          f"interval coverage {covered}/{total}")  # fmt: skip
    assert missed == 0
    assert rate <= 0.10
    assert right >= 0.6 * runs
    assert covered >= 0.85 * total


def test_one_white_noise_data_set() -> None:
    rng = np.random.default_rng(2)
    X, names = _candidates(rng)
    z0 = X @ _truth(names)
    sw = stepwise(z0 + 0.02 * np.std(z0) * rng.standard_normal(z0.size), X, names)
    assert set(sw.names) == set(TRUE)
    assert np.all(np.abs(sw.fit.theta - _truth(sw.names)) <= sw.fit.ci95_halfwidth)
    assert sw.fit.max_lag <= 3  # white residuals
    assert sw.not_identifiable == ()


def _entered_then_removed() -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``xa = x1 + x2 + noise`` enters first, then x1 and x2 make it redundant and it is removed."""
    rng = np.random.default_rng(1)
    n = 500
    x1, x2, x3 = rng.standard_normal((3, n))
    xa = x1 + x2 + 0.3 * rng.standard_normal(n)
    X = np.column_stack([np.ones(n), xa, x1, x2, x3])
    z = 1.0 + x1 + x2 + 0.5 * rng.standard_normal(n)
    return z, X, ["bias", "xa", "x1", "x2", "x3"]


def test_partial_f_is_the_nested_model_f_test() -> None:
    z, X, names = _entered_then_removed()
    sw = stepwise(z, X, names, forced=["bias"])
    assert [(s.action, s.name) for s in sw.steps][:4] == [
        ("enter", "xa"),
        ("enter", "x2"),
        ("enter", "x1"),
        ("remove", "xa"),
    ]
    before: tuple[str, ...] = ("bias",)
    for s in sw.steps:
        big, small = (s.included, before) if s.action == "enter" else (before, s.included)
        full = sm.OLS(z, X[:, [names.index(n) for n in big]]).fit()
        restricted = sm.OLS(z, X[:, [names.index(n) for n in small]]).fit()
        f_value, _, df_diff = full.compare_f_test(restricted)
        assert df_diff == 1
        assert s.f_value == pytest.approx(f_value, rel=1e-9)
        before = s.included
    idx = [names.index(n) for n in sw.names]
    r2 = sm.OLS(z, X[:, idx]).fit().rsquared  # centred: the model has a constant
    assert sw.steps[-1].r_squared_pct == pytest.approx(100.0 * r2, rel=1e-12)


def test_coloured_residuals_corrected_intervals_cover() -> None:
    """AR(1) residuals (phi 0.9) on smooth regressors: the ordinary intervals are far too narrow, the
    corrected ones cover the true parameters close to 95 % over 200 seeded repetitions."""
    theta, n, reps = np.array([0.5, 2.0, -1.0]), 1000, 200
    cover, cover_white, ratio = np.zeros(3), np.zeros(3), []
    for rep in range(reps):
        rng = np.random.default_rng(1000 + rep)
        X = np.column_stack([np.ones(n), _ar1(rng, n, 0.95), _ar1(rng, n, 0.9)])
        f = fit(X @ theta + 0.5 * _ar1(rng, n, 0.9), X, ["bias", "a", "b"])
        cover += np.abs(f.theta - theta) <= f.ci95_halfwidth
        cover_white += np.abs(f.theta - theta) <= f.ci95_halfwidth_white
        ratio.append(f.se / f.se_white)
    cover, cover_white, r = cover / reps, cover_white / reps, np.array(ratio)
    print(f"AR(1) 0.9, {reps} runs: corrected coverage {np.round(cover, 3)}, ordinary {np.round(cover_white, 3)}, "
          f"se ratio mean {np.round(r.mean(axis=0), 2)}")  # fmt: skip
    assert np.all(r > 1.0)
    assert np.all((cover >= 0.88) & (cover <= 0.99))
    assert np.all(cover_white < 0.6)


def test_max_lag_follows_the_residual_autocorrelation() -> None:
    rng = np.random.default_rng(5)
    assert coloured_max_lag(rng.standard_normal(2000)) <= 3
    lag = coloured_max_lag(_ar1(rng, 2000, 0.9))
    assert 15 <= lag <= 60  # 0.9^k reaches the band 1.96 / sqrt(2000) = 0.044 near k = 30
    assert coloured_max_lag(_ar1(rng, 2000, 0.999), cap=50) == 50


def test_zero_and_duplicate_columns_are_not_entered() -> None:
    X, names = _candidates(np.random.default_rng(3), 1000)
    z = X @ _truth(names)
    extra = np.column_stack([np.zeros(X.shape[0]), X[:, names.index("dt")], 7.0 * np.ones(X.shape[0])])
    X2, names2 = np.column_stack([X, extra]), [*names, "zero", "dt_copy", "seven"]
    sw = stepwise(z, X2, names2)
    assert set(sw.names) == set(TRUE)
    reasons = dict(sw.not_excited)
    assert set(reasons) == {"zero", "dt_copy", "seven"}
    assert "zero" in reasons["zero"]
    assert "dt" in reasons["dt_copy"] and "collinear" in reasons["dt_copy"]
    assert "bias" in reasons["seven"]
    with pytest.raises(ValueError, match="dt_copy: collinear with dt"):
        fit(z, X2[:, [5, 13]], ["dt", "dt_copy"])
    with pytest.raises(ValueError, match="zero: identically zero"):
        fit(z, X2[:, [0, 12]], ["bias", "zero"])


def test_prune_removes_insignificant_but_keeps_forced() -> None:
    rng = np.random.default_rng(11)
    n = 400
    x1, n1, n2, n3 = rng.standard_normal((4, n))
    X = np.column_stack([np.ones(n), x1, n1 * 1e-3, n2, n3])
    names = ["bias", "x1", "null1", "null2", "null3"]
    z = 0.5 + 2.0 * x1 + rng.standard_normal(n)
    full = fit(z, X, names)
    assert set(full.insignificant) == {"null1", "null2", "null3"}
    pruned = prune_insignificant(z, X, names)
    assert set(pruned.fit.names) == {"bias", "x1"}
    assert set(pruned.removed) == {"null1", "null2", "null3"}
    assert pruned.fit.insignificant == ()
    kept = prune_insignificant(z, X, names, forced=["null1"])
    assert "null1" in kept.fit.names and "null1" not in kept.removed


def test_fit_fields_and_prediction() -> None:
    rng = np.random.default_rng(4)
    X = np.column_stack([np.ones(300), rng.standard_normal(300)])
    z = X @ np.array([1.0, -3.0]) + 0.1 * rng.standard_normal(300)
    f = fit(z, X, ["bias", "x"])
    ref = sm.OLS(z, X).fit()
    np.testing.assert_allclose(f.theta, ref.params, rtol=1e-12)
    np.testing.assert_allclose(f.se_white, ref.bse, rtol=1e-10)
    assert f.s_squared == pytest.approx(ref.scale, rel=1e-12)
    assert f.r_squared_pct == pytest.approx(100.0 * ref.rsquared, rel=1e-12)
    assert (f.n_params, f.n_samples) == (2, 300)
    np.testing.assert_allclose(f.predict(X[:5]), ref.fittedvalues[:5], rtol=1e-12)
    np.testing.assert_allclose(f.partial_f, ref.tvalues**2, rtol=1e-9)
    with pytest.raises(ValueError, match="shape"):
        f.predict(X[:, :1])
    empty = fit(z, X[:, :0], [])
    assert empty.n_params == 0 and empty.s_squared == pytest.approx(np.mean(z**2))


def test_bad_inputs_are_named() -> None:
    X = np.column_stack([np.ones(10), np.arange(10.0)])
    z = np.arange(10.0) ** 2
    with pytest.raises(ValueError, match="z has 1 non-finite"):
        fit(np.where(np.arange(10) == 3, np.nan, z), X, ["bias", "t"])
    Xn = X.copy()
    Xn[4, 1] = np.inf
    with pytest.raises(ValueError, match="regressor 't'"):
        fit(z, Xn, ["bias", "t"])
    with pytest.raises(ValueError, match="distinct"):
        fit(z, X, ["a", "a"])
    with pytest.raises(ValueError, match="f_remove"):
        stepwise(z, X, ["bias", "t"], f_enter=2.0, f_remove=4.0)
    with pytest.raises(ValueError, match="not among the candidates"):
        stepwise(z, X, ["bias", "t"], forced=["nope"])


def test_metrics_by_hand() -> None:
    z = np.array([1.0, 2.0, 3.0, 4.0])
    y = np.array([1.0, 2.0, 2.0, 5.0])
    # residuals 0, 0, 1, -1: SSR 2; mean z 2.5, SST 5; rms(z - y) = sqrt(0.5); range z = 3
    assert r_squared(z, y) == pytest.approx(1.0 - 2.0 / 5.0)
    assert s_squared(z, y, 1) == pytest.approx(2.0 / 3.0)
    assert tic(z, y) == pytest.approx(math.sqrt(0.5) / (math.sqrt(30.0 / 4.0) + math.sqrt(34.0 / 4.0)))
    assert nrmse(z, y) == pytest.approx(math.sqrt(0.5) / 3.0)
    assert tic(z, z) == 0.0
    assert tic(z, np.zeros(4)) == 1.0
    assert r_squared(z, z) == 1.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: tic(np.zeros(3), np.zeros(3)), "both all zero"),
        (lambda: nrmse(np.ones(3), np.zeros(3)), "range is zero"),
        (lambda: r_squared(np.ones(3), np.zeros(3)), "constant"),
        (lambda: s_squared(np.ones(3), np.zeros(3), 3), "n_params"),
        (lambda: tic(np.array([1.0, np.nan]), np.zeros(2)), "z has 1 non-finite"),
        (lambda: nrmse(np.arange(3.0), np.zeros(2)), "differ in length"),
        (lambda: r_squared(np.zeros((2, 2)), np.zeros((2, 2))), "1-D"),
    ],
)
def test_metrics_refuse_undefined_cases(call: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()  # type: ignore[operator]
