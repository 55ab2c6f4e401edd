"""Step-wise regression and pruning of unidentifiable parameters (Klein & Morelli, *Aircraft System
Identification*, 2006, ch. 5.4; the paper's model structure determination).

``stepwise`` chooses regressors from candidate columns by partial F statistics, as Klein & Morelli's
step-wise regression does (Efroymson's algorithm): starting from the ``forced`` regressors, each step

1. enters the candidate with the largest partial F when entered, if that F exceeds ``f_enter``. The
   partial F of a candidate is the square of its t statistic (ordinary covariance) in the model with
   it, which equals the F of the nested comparison ``((SSR_without - SSR_with) / 1) / s^2_with``
   (statsmodels ``compare_f_test``);
2. then removes, one at a time and refitting in between, each included regressor (never a forced one)
   whose partial F in the current model is below ``f_remove``, the smallest first;

and stops when a step changes nothing (or after ``max_steps`` changes: ``Stepwise.converged`` is then
False). Every change is recorded (``Stepwise.steps``) with its F and the model's R^2 and s^2 after it.

A bias is not added: pass a column of ones named e.g. ``"bias"`` and force it or let it compete.

Candidates that are identically zero, or collinear with the included regressors (a duplicate, or a
regressor the manoeuvre did not excite independently), are never entered; those that are zero or
collinear with the final model are reported in ``Stepwise.not_excited`` with the reason. The final
model is fitted with ``identify.regression.fit`` (coloured-residual corrected intervals), and
``Stepwise.not_identifiable`` lists the regressors whose 95 % interval contains zero; the paper removed
those, which ``prune_insignificant`` does: refit without the least significant of them, repeat until
every remaining one is significant or forced.

F statistics use the ordinary (white-residual) variance, as Klein & Morelli's do; the intervals that
decide identifiability use the corrected one. With a noise-free (exactly fitting) model the partial F
use a floor on s^2 (``identify.regression.EXACT_RTOL``), so round-off cannot enter a regressor.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np

from identify.metrics import r_squared, s_squared
from identify.regression import Fit, check_data, collinearity, fit, ols, partial_f


@dataclass(frozen=True)
class Step:
    """One change of the model: ``name`` entered or removed with partial F ``f_value``; the model
    after it has regressors ``included``, R^2 ``r_squared_pct`` (%) and fit error variance
    ``s_squared`` (units of z, squared)."""

    action: Literal["enter", "remove"]
    name: str
    f_value: float
    r_squared_pct: float
    s_squared: float
    included: tuple[str, ...]


class NotExcited(NamedTuple):
    """A candidate regressor that could not be estimated from these data, and why."""

    name: str
    reason: str


@dataclass(frozen=True, eq=False)
class Stepwise:
    """The result of ``stepwise``.

    Attributes:
        names: the chosen regressors, in candidate column order.
        indices: their columns in the candidate matrix.
        fit: the final model's fit (``identify.regression.Fit``).
        steps: every enter / remove, in order.
        not_excited: candidates that are zero or collinear with the final model.
        not_identifiable: chosen regressors whose corrected 95 % interval contains zero.
        forced: the forced regressors.
        converged: False if ``max_steps`` changes were made without settling.
    """

    names: tuple[str, ...]
    indices: tuple[int, ...]
    fit: Fit
    steps: tuple[Step, ...]
    not_excited: tuple[NotExcited, ...]
    not_identifiable: tuple[str, ...]
    forced: tuple[str, ...]
    converged: bool


@dataclass(frozen=True, eq=False)
class Pruned:
    """The result of ``prune_insignificant``: the final fit, and the regressors removed, in order."""

    fit: Fit
    removed: tuple[str, ...]


def stepwise(
    z: np.ndarray,
    X: np.ndarray,
    names: Sequence[str],
    *,
    f_enter: float = 4.0,
    f_remove: float = 4.0,
    forced: Sequence[str] = (),
    max_steps: int = 100,
) -> Stepwise:
    """Step-wise regression of ``z`` (N,) on candidate regressors ``X`` (N, n) named ``names`` (see
    the module docstring). ``f_remove`` must not exceed ``f_enter`` (else a regressor could cycle).

    Raises:
        ValueError: bad data (see ``identify.regression.check_data``), unknown or degenerate forced
            regressors, ``f_remove > f_enter``.
    """
    zz, XX, nm = check_data(z, X, names)
    if f_remove > f_enter:
        raise ValueError(f"f_remove ({f_remove}) must not exceed f_enter ({f_enter})")
    included = _forced_columns(XX, nm, forced)
    forced_set = frozenset(included)
    steps: list[Step] = []
    converged = False
    while len(steps) < max_steps:
        changed = False
        entry = _best_entry(zz, XX, nm, included)
        if entry is not None and entry[1] > f_enter:
            included = sorted([*included, entry[0]])
            steps.append(_step("enter", nm[entry[0]], entry[1], zz, XX, nm, included))
            changed = True
        while len(steps) < max_steps:
            removal = _worst_removal(zz, XX, included, forced_set)
            if removal is None or removal[1] >= f_remove:
                break
            included = [i for i in included if i != removal[0]]
            steps.append(_step("remove", nm[removal[0]], removal[1], zz, XX, nm, included))
            changed = True
        if not changed:
            converged = True
            break
    final = fit(zz, XX[:, included], [nm[i] for i in included])
    not_excited = [
        NotExcited(nm[j], why)
        for j in range(len(nm))
        if j not in included and (why := collinearity(XX, nm, included, j))
    ]
    return Stepwise(
        names=final.names,
        indices=tuple(included),
        fit=final,
        steps=tuple(steps),
        not_excited=tuple(not_excited),
        not_identifiable=final.insignificant,
        forced=tuple(nm[i] for i in sorted(forced_set)),
        converged=converged,
    )


def prune_insignificant(
    z: np.ndarray, X: np.ndarray, names: Sequence[str], *, forced: Sequence[str] = (), max_lag: int | None = None
) -> Pruned:
    """Refit ``z`` on ``X`` without the regressors whose corrected 95 % interval contains zero, one at a
    time (the least significant first: smallest ``|theta| / half-width``), until every remaining one is
    significant or forced. ``X`` and ``names`` are the model's columns, e.g. ``X[:, sw.indices]`` and
    ``sw.names`` of a ``Stepwise``; ``max_lag`` is passed to ``identify.regression.fit``."""
    zz, XX, nm = check_data(z, X, names)
    keep = set(_forced_columns(XX, nm, forced))
    cols = list(range(len(nm)))
    removed: list[str] = []
    while True:
        current = fit(zz, XX[:, cols], [nm[i] for i in cols], max_lag=max_lag)
        worst, worst_ratio = -1, np.inf
        for pos, j in enumerate(cols):
            hw, th = current.ci95_halfwidth[pos], abs(current.theta[pos])
            if j in keep or th > hw:
                continue
            ratio = th / hw if hw > 0.0 else 0.0
            if ratio < worst_ratio:
                worst, worst_ratio = j, ratio
        if worst < 0:
            return Pruned(fit=current, removed=tuple(removed))
        cols.remove(worst)
        removed.append(nm[worst])


def _forced_columns(X: np.ndarray, names: tuple[str, ...], forced: Sequence[str]) -> list[int]:
    unknown = [f for f in forced if f not in names]
    if unknown:
        raise ValueError(f"forced regressors not among the candidates: {unknown}")
    cols = sorted({names.index(f) for f in forced})
    for k, j in enumerate(cols):
        why = collinearity(X, names, cols[:k], j)
        if why:
            raise ValueError(f"forced regressor {names[j]!r} cannot be estimated: {why}")
    return cols


def _best_entry(z: np.ndarray, X: np.ndarray, names: tuple[str, ...], included: list[int]) -> tuple[int, float] | None:
    """The excluded, estimable candidate with the largest partial F when entered, and that F."""
    best: tuple[int, float] | None = None
    for j in range(X.shape[1]):
        if j in included or collinearity(X, names, included, j):
            continue
        cols = [*included, j]
        res, _ = ols(z, X[:, cols])
        f = float(partial_f(res, z)[-1])
        if best is None or f > best[1]:
            best = (j, f)
    return best


def _worst_removal(
    z: np.ndarray, X: np.ndarray, included: list[int], forced: frozenset[int]
) -> tuple[int, float] | None:
    """The included, non-forced regressor with the smallest partial F in the current model, and that F."""
    free = [pos for pos, j in enumerate(included) if j not in forced]
    if not free:
        return None
    res, _ = ols(z, X[:, included])
    f = partial_f(res, z)
    pos = min(free, key=lambda p: f[p])
    return included[pos], float(f[pos])


def _step(
    action: Literal["enter", "remove"],
    name: str,
    f_value: float,
    z: np.ndarray,
    X: np.ndarray,
    names: tuple[str, ...],
    included: list[int],
) -> Step:
    if included:
        res, _ = ols(z, X[:, included])
        y = np.asarray(res.fittedvalues)
    else:
        y = np.zeros_like(z)
    return Step(
        action=action,
        name=name,
        f_value=f_value,
        r_squared_pct=100.0 * r_squared(z, y),
        s_squared=s_squared(z, y, len(included)),
        included=tuple(names[i] for i in included),
    )
