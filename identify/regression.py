"""Equation-error least squares with coloured-residual corrected standard errors (Klein & Morelli,
*Aircraft System Identification*, 2006, ch. 5; the paper's Tables 1 and 5).

The model is ``z = X theta + v``: ``z`` (N,) the measured output (e.g. a force, N), ``X`` (N, n_p) the
regressors, one column per named parameter, ``theta`` the parameters (units of z per unit of their
regressor). ``fit`` solves it with statsmodels' OLS and reports, per parameter:

- ``se_white``: the ordinary standard error, ``s^2 (X'X)^-1`` with ``s^2 = sum v^2 / (N - n_p)``, right
  only for white residuals;
- ``se``: the standard error corrected for coloured residuals. Equation-error residuals of flight data
  are coloured (model error is smooth in time), and the ordinary errors are then too small, often
  several times (Morelli & Klein, "Accuracy of aircraft dynamic stability and control derivatives from
  flight test data", J. Aircraft 34(1), 1997; Klein & Morelli ch. 5.2.2). Morelli & Klein's estimate is
  ``(X'X)^-1 [sum_i sum_j x_i R_vv(i - j) x_j'] (X'X)^-1`` with ``R_vv`` the residual autocorrelation.
  Here it is statsmodels' HAC (heteroskedasticity and autocorrelation consistent) covariance with the
  uniform kernel and maximum lag ``L``: ``(X'X)^-1 [sum_{|i - j| <= L} x_i v_i v_j x_j'] (X'X)^-1``,
  scaled by ``N / (N - n_p)``. The two are not the same formula: Morelli & Klein's replaces each
  ``v_i v_j`` by the time average ``R_vv(i - j)`` over all lags, the HAC form keeps the individual
  products within ``L`` lags. Both estimate the same covariance (they agree in expectation for
  stationary residuals independent of the regressors). In 1000 seeded runs of the AR(1) set-up of
  ``tests/test_identify_regression.py`` (residual AR coefficient 0.9, smooth regressors, N = 1000)
  the 95 % intervals covered 90-92 % of the time with the HAC form, 92-94 % with Morelli & Klein's
  form at the same lag, 36-46 % with the ordinary errors;
- ``L`` is the first lag at which the residual autocorrelation (statsmodels ``acf``) falls inside the
  95 % band of white noise, ``+-1.96 / sqrt(N)``, capped at ``N // 4`` (``coloured_max_lag``). Lags
  kept beyond that add estimation noise (in 400 runs of that experiment, 1.5 to 3 times that lag covered
  less, not more) and, with the uniform kernel, can make the covariance indefinite: when a variance
  comes out non-positive, the Bartlett (Newey-West) kernel at the same lag, which is positive
  semi-definite, is used instead and ``Fit.hac_kernel`` says so (3 of the 1000 runs);
- ``ci95_halfwidth``: ``t_{0.975, N - n_p} se`` (and the same with ``se_white``); a parameter whose
  interval contains zero is listed in ``Fit.insignificant`` (the paper dropped those).

The fit is computed on regressors scaled to unit RMS (better conditioning; parameters, covariances and
F statistics are mapped back and are those of the unscaled problem). Non-finite data, zero or collinear
regressor columns are refused with a ``ValueError`` naming them; ``identify.stepwise`` screens
candidates for that instead.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats
from statsmodels.regression.linear_model import OLS, RegressionResults
from statsmodels.tsa.stattools import acf

from identify.metrics import as_finite_1d, r_squared, s_squared

#: A regressor whose part outside the span of other regressors is below this fraction of its norm is
#: treated as collinear with them (its parameter is not identifiable from the data).
COLLINEAR_RTOL = 1e-8
#: Residuals whose RMS is below this fraction of rms(z) are round-off (the model fits exactly): the
#: partial F statistics use this floor for s^2 rather than a ratio of round-off errors.
EXACT_RTOL = 1e-10
#: Confidence level of the intervals.
CONFIDENCE = 0.95


@dataclass(frozen=True, eq=False)
class Fit:
    """An equation-error least-squares fit ``z = X theta + v`` (see the module docstring).

    Attributes:
        names: parameter (regressor) names, in column order.
        theta: estimates (units of z per unit of the regressor).
        se, se_white: standard errors, corrected for coloured residuals and ordinary.
        ci95_halfwidth, ci95_halfwidth_white: 95 % interval half-widths from ``se`` and ``se_white``.
        cov, cov_white: the corresponding covariance matrices (n_p, n_p).
        partial_f: each parameter's partial F (t^2 from the ordinary covariance: the F of dropping it).
        r_squared_pct: coefficient of determination (%), about the mean of z.
        s_squared: fit error variance ``sum v^2 / (N - n_p)`` (units of z, squared).
        n_params, n_samples: n_p and N.
        max_lag: the HAC lag ``L`` (samples).
        hac_kernel: ``"uniform"``, or ``"bartlett"`` if the uniform kernel gave a non-positive variance.
        residuals: ``z - X theta`` (N,).
    """

    names: tuple[str, ...]
    theta: np.ndarray
    se: np.ndarray
    se_white: np.ndarray
    ci95_halfwidth: np.ndarray
    ci95_halfwidth_white: np.ndarray
    cov: np.ndarray
    cov_white: np.ndarray
    partial_f: np.ndarray
    r_squared_pct: float
    s_squared: float
    n_params: int
    n_samples: int
    max_lag: int
    hac_kernel: str
    residuals: np.ndarray

    def __post_init__(self) -> None:
        for v in vars(self).values():
            if isinstance(v, np.ndarray):
                v.setflags(write=False)

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Model output ``X theta`` for regressors ``X`` (M, n_params), same columns as the fit."""
        XX = np.asarray(X, dtype=float)
        if XX.ndim != 2 or XX.shape[1] != self.n_params:
            raise ValueError(f"X must have shape (M, {self.n_params}), got {XX.shape}")
        return XX @ self.theta

    @property
    def insignificant(self) -> tuple[str, ...]:
        """Parameters whose corrected 95 % interval contains zero ("not identifiable")."""
        crosses = np.abs(self.theta) <= self.ci95_halfwidth
        return tuple(n for n, c in zip(self.names, crosses, strict=True) if c)


def fit(z: np.ndarray, X: np.ndarray, names: Sequence[str], *, max_lag: int | None = None) -> Fit:
    """Equation-error least squares ``z = X theta + v`` (see the module docstring).

    Args:
        z: measured output (N,), finite.
        X: regressors (N, n_p), finite, no zero or collinear column; n_p may be 0 (the model ``y = 0``).
        names: one distinct name per column.
        max_lag: the HAC lag; default chosen from the residual autocorrelation (``coloured_max_lag``).

    Raises:
        ValueError: naming the problem (non-finite values, shapes, names, N <= n_p, degenerate columns).
    """
    zz, XX, nm = check_data(z, X, names)
    N, n_p = XX.shape
    bad = degenerate_columns(XX, nm)
    if bad:
        raise ValueError(
            "regressors not identifiable from these data: " + "; ".join(f"{k}: {v}" for k, v in bad.items())
        )
    if n_p == 0:
        return _fit_nothing(zz)
    res, d = ols(zz, XX)
    lag = coloured_max_lag(res.resid) if max_lag is None else int(max_lag)
    if lag < 0:
        raise ValueError(f"max_lag must be >= 0, got {lag}")
    cov_scaled, kernel = _hac_cov(res, lag)
    unscale = np.outer(d, d)
    cov = cov_scaled / unscale
    cov_white = np.asarray(res.cov_params()) / unscale
    theta = np.asarray(res.params) / d
    # (clipped: a Bartlett covariance of round-off residuals can have variances of -1e-40)
    se, se_white = np.sqrt(np.clip(np.diag(cov), 0.0, None)), np.sqrt(np.diag(cov_white))
    q = float(stats.t.ppf(0.5 + CONFIDENCE / 2.0, N - n_p))
    y_hat = XX @ theta
    return Fit(
        names=nm,
        theta=theta,
        se=se,
        se_white=se_white,
        ci95_halfwidth=q * se,
        ci95_halfwidth_white=q * se_white,
        cov=cov,
        cov_white=cov_white,
        partial_f=partial_f(res, zz),
        r_squared_pct=100.0 * r_squared(zz, y_hat),
        s_squared=s_squared(zz, y_hat, n_p),
        n_params=n_p,
        n_samples=N,
        max_lag=lag,
        hac_kernel=kernel,
        residuals=zz - y_hat,
    )


def coloured_max_lag(residuals: np.ndarray, cap: int | None = None) -> int:
    """The HAC lag for ``residuals``: the first lag whose autocorrelation is inside the 95 % band of
    white noise (``|r_k| < z_{0.975} / sqrt(N)``), at most ``cap`` (default ``N // 4``)."""
    v = as_finite_1d("residuals", residuals)
    n = v.size
    cap = max(1, n // 4) if cap is None else cap
    if cap < 1 or n < 3 or not np.any(v - v.mean()):
        return 0
    r = acf(v, nlags=min(cap, n - 1), fft=True)
    band = float(stats.norm.ppf(0.5 + CONFIDENCE / 2.0)) / math.sqrt(n)
    inside = np.nonzero(np.abs(r[1:]) < band)[0]
    return int(inside[0]) + 1 if inside.size else min(cap, n - 1)


def check_data(z: np.ndarray, X: np.ndarray, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """``z`` (N,), ``X`` (N, n) and ``names`` (n distinct) as checked float arrays and a tuple, or
    ``ValueError`` naming the problem (a non-finite regressor is named by its column name)."""
    zz = as_finite_1d("z", z)
    XX = np.asarray(X, dtype=float)
    if XX.ndim != 2 or XX.shape[0] != zz.size:
        raise ValueError(f"X must have shape ({zz.size}, n) to match z, got {XX.shape}")
    nm = tuple(str(n) for n in names)
    if len(nm) != XX.shape[1]:
        raise ValueError(f"{len(nm)} names for {XX.shape[1]} regressor columns")
    if len(set(nm)) != len(nm):
        raise ValueError(f"regressor names must be distinct, got {nm}")
    for j, n in enumerate(nm):
        as_finite_1d(f"regressor {n!r}", XX[:, j])
    if zz.size <= XX.shape[1]:
        raise ValueError(f"need more samples than parameters, got N={zz.size}, n_p={XX.shape[1]}")
    return zz, XX, nm


def ols(z: np.ndarray, X: np.ndarray) -> tuple[RegressionResults, np.ndarray]:
    """statsmodels OLS of ``z`` on ``X`` with each column scaled to unit RMS, and the scales ``d``
    (the unscaled parameters are ``params / d``). Columns must be non-zero."""
    d = np.sqrt(np.mean(X * X, axis=0))
    return OLS(z, X / d).fit(), d


def partial_f(res: RegressionResults, z: np.ndarray) -> np.ndarray:
    """Partial F of each parameter of an OLS fit: ``theta_j^2 / var_j`` with the ordinary variance,
    i.e. ``t_j^2``, equal to the F of the nested comparison without parameter j. ``s^2`` is floored at
    ``(EXACT_RTOL rms(z))^2`` so that an exact (noise-free) fit does not divide round-off by round-off."""
    floor = EXACT_RTOL**2 * float(np.mean(z * z))
    s2 = max(float(res.scale), floor)
    return np.asarray(res.params) ** 2 / (s2 * np.diag(res.normalized_cov_params))


def degenerate_columns(X: np.ndarray, names: Sequence[str]) -> dict[str, str]:
    """Columns of ``X`` that are zero or collinear with the columns before them (taken greedily in
    column order), with the reason; empty if all columns are independent."""
    kept: list[int] = []
    out: dict[str, str] = {}
    for j in range(X.shape[1]):
        reason = collinearity(X, names, kept, j)
        if reason:
            out[names[j]] = reason
        else:
            kept.append(j)
    return out


def collinearity(X: np.ndarray, names: Sequence[str], included: Sequence[int], j: int) -> str:
    """Why column ``j`` cannot be estimated beside columns ``included`` ("" if it can)."""
    x = X[:, j]
    nx = float(np.linalg.norm(x))
    if nx == 0.0:
        return "identically zero (not excited)"
    if not included:
        return ""
    A = X[:, list(included)]
    na = np.linalg.norm(A, axis=0)
    na[na == 0.0] = 1.0
    c, *_ = np.linalg.lstsq(A / na, x / nx, rcond=None)
    outside = float(np.linalg.norm(x / nx - (A / na) @ c))
    if outside >= COLLINEAR_RTOL:
        return ""
    partners = [names[i] for i, ci in zip(included, c, strict=True) if abs(ci) > 1e-6]
    return f"collinear with {', '.join(partners)} (part outside their span {outside:.1e} of its norm)"


def _hac_cov(res: RegressionResults, lag: int) -> tuple[np.ndarray, str]:
    cov = np.zeros((0, 0))
    for kernel in ("uniform", "bartlett"):
        robust = res.get_robustcov_results(cov_type="HAC", maxlags=lag, kernel=kernel, use_correction=True)
        cov = np.asarray(robust.cov_params())
        if np.all(np.diag(cov) > 0.0) or not np.any(res.resid):
            return cov, kernel
    return cov, "bartlett"


def _fit_nothing(z: np.ndarray) -> Fit:
    """The empty model ``y = 0``."""
    e = np.zeros(0)
    return Fit(
        names=(),
        theta=e,
        se=e,
        se_white=e,
        ci95_halfwidth=e,
        ci95_halfwidth_white=e,
        cov=np.zeros((0, 0)),
        cov_white=np.zeros((0, 0)),
        partial_f=e,
        # A constant z (a synthetic or a clipped record) has no variance to explain: R^2 is 0, not undefined.
        r_squared_pct=100.0 * r_squared(z, np.zeros_like(z)) if np.ptp(z) > 0.0 else 0.0,
        s_squared=s_squared(z, np.zeros_like(z), 0),
        n_params=0,
        n_samples=z.size,
        max_lag=0,
        hac_kernel="uniform",
        residuals=z.copy(),
    )
