"""The paper's system identification of Eq. 46 for any vehicle: step-wise regression, equation error,
coloured-residual intervals, fit and prediction metrics (paper Tables 1, 3, 4, 5).

Per axis (X, Y, Z, L, M, N): the candidates are every Eq. 46 term of that axis (the paper's model
structure, including the terms its regression dropped and Assumption 1's rate terms);
step-wise regression (F-to-enter and F-to-remove, :func:`identify.stepwise.stepwise`) chooses the
structure, then the regressors whose 95 % interval (corrected for coloured residuals) crosses zero are
removed one at a time and the rest refitted, as the paper did ("large standard errors and 95 %
confidence intervals crossing zero ... were removed"). Reported per axis: R^2 and s^2 on the fitting
manoeuvre (Table 1), Theil's inequality coefficient and the NRMSE on the fitting and on the
independent validation manoeuvre (Table 4), the estimates and their 95 % intervals (Table 5), and the
identified domain (Table 3). Candidates the manoeuvre did not excite are named, never fitted.

A bias on the horizontal forces (X, Y), always in the regression (Klein and Morelli's equation error
carries one per equation): the accelerometer's turn-on bias of that flight, not the vehicle's. Every
X and Y term is odd in an airspeed or a rate, so an unmodelled bias of 0.02 m/s^2 (2.8 kg: 0.056 N) would
otherwise bend the drag terms by as much (measured: the identified drag 0.06-0.09 N too steep at 2-8
m/s, the open-field wind read 0.6 m/s short). It is reported (``AxisResult.bias``), not written to the
vehicle's model; on the validation manoeuvre, another flight with its own bias, it is estimated again
(the mean residual) before the prediction metrics. Not on Z (the thrust's terms are nearly collinear
with a constant over a hover's rotor speeds; the wind estimator carries a body-z accelerometer bias of
its own) nor on the moments (a constant moment is trimmed by the controller into delta_a, delta_e).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from identify.flight_data import FlightData
from identify.measure import EquationError, domain_limits, domain_table, equation_error
from identify.metrics import nrmse, tic
from identify.stepwise import prune_insignificant, stepwise
from vehicle.params import COEFFICIENT_NAMES, VehicleParams
from vehicle.rotor_model import AXIS_NAMES, AXIS_OF


@dataclass(frozen=True)
class AxisResult:
    """One axis: the chosen regressors with estimates and 95 % half-widths (SI), the metrics, and what
    could not be identified (name -> reason)."""

    axis: str
    names: tuple[str, ...]
    theta: tuple[float, ...]
    ci95: tuple[float, ...]
    r2_pct: float
    s2: float
    fit_tic: float
    fit_nrmse: float
    val_tic: float | None
    val_nrmse: float | None
    not_identified: dict[str, str]
    steps: tuple[str, ...]
    #: The fitted constant (N) and its 95 % half-width on the X and Y axes: the flight's accelerometer
    #: bias times the mass, not part of the model (see the module docstring). None on the other axes.
    bias: tuple[float, float] | None = None


@dataclass(frozen=True)
class Identification:
    """The whole identification: per-axis results, the coefficients (SI), the domain, the data used."""

    axes: dict[str, AxisResult]
    coefficients: dict[str, float]
    ci95: dict[str, float]
    domain: dict[str, list[float]]
    domain_airspeed_m_s: float
    domain_vertical_airspeed_m_s: float
    n_fit: int
    n_validation: int
    exclusions: tuple[str, ...]
    wind_assumed_ned: tuple[float, float, float]
    sources: tuple[str, ...] = field(default_factory=tuple)
    #: The equation-error data of the fitting and the validation manoeuvre (for plots).
    data: tuple[EquationError, EquationError | None] | None = field(default=None, repr=False)

    def table(self) -> dict[str, dict[str, float | None]]:
        """Per axis: R^2 in percent, s^2, and TIC / NRMSE on the fitting and the validation manoeuvre."""
        return {a: {"r2_pct": r.r2_pct, "s2": r.s2, "fit_tic": r.fit_tic, "fit_nrmse": r.fit_nrmse,
                    "val_tic": r.val_tic, "val_nrmse": r.val_nrmse} for a, r in self.axes.items()}  # fmt: skip


#: The axes whose regression carries a bias (X, Y; see the module docstring) and its column's name.
BIAS_AXES = (0, 1)
BIAS = "bias"


def _axis(k: int, ee: EquationError, val: EquationError | None, f_enter: float) -> AxisResult:
    cand = [i for i in range(len(COEFFICIENT_NAMES)) if AXIS_OF[i] == k]
    names = [COEFFICIENT_NAMES[i] for i in cand]
    use = ee.use
    z = ee.z[use, k]
    X = ee.X[use][:, cand]
    forced: tuple[str, ...] = ()
    if k in BIAS_AXES:
        X = np.column_stack([X, np.ones(X.shape[0])])
        names = [*names, BIAS]
        forced = (BIAS,)
    sw = stepwise(z, X, names, f_enter=f_enter, f_remove=f_enter, forced=forced)
    not_identified = {ne.name: ne.reason for ne in sw.not_excited}
    cols = list(sw.indices)
    pr = prune_insignificant(z, X[:, cols], [names[i] for i in cols], forced=forced)
    for name in pr.removed:
        not_identified[name] = "chosen by step-wise regression but its 95 % interval crosses zero: not identifiable"
    for name in names:
        if name not in pr.fit.names and name not in not_identified:
            not_identified[name] = "not chosen by step-wise regression (partial F below F-to-enter)"
    f = pr.fit
    full = np.zeros(len(names))
    for n, th in zip(f.names, f.theta, strict=True):
        full[names.index(n)] = th
    y_fit = X @ full
    val_tic = val_nrmse = None
    if val is not None:
        zv = val.z[val.use, k]
        yv = val.X[val.use][:, cand] @ full[: len(cand)]
        if forced:  # the validation flight's own accelerometer bias
            yv = yv + float(np.mean(zv - yv))
        val_tic, val_nrmse = tic(zv, yv), nrmse(zv, yv)
    steps = tuple(f"{s.action} {s.name} (F {s.f_value:.3g}, R^2 {s.r_squared_pct:.2f} %)" for s in sw.steps)
    steps += tuple(f"remove {n} (95 % interval crosses zero)" for n in pr.removed)
    model = [i for i, n in enumerate(f.names) if n != BIAS]
    bias = None
    if forced:
        j = f.names.index(BIAS)
        bias = (float(f.theta[j]), float(f.ci95_halfwidth[j]))
    return AxisResult(axis=AXIS_NAMES[k], names=tuple(f.names[i] for i in model),
                      theta=tuple(float(f.theta[i]) for i in model),
                      ci95=tuple(float(f.ci95_halfwidth[i]) for i in model), r2_pct=float(f.r_squared_pct),
                      s2=float(f.s_squared), fit_tic=tic(z, y_fit), fit_nrmse=nrmse(z, y_fit), val_tic=val_tic,
                      val_nrmse=val_nrmse, not_identified=not_identified, steps=steps, bias=bias)  # fmt: skip


def identify(fit_data: FlightData, vehicle: VehicleParams, validation: FlightData | None = None,
             f_enter: float = 4.0, rate_hz: float = 50.0,
             domain_m_s: tuple[float, float] | None = None) -> Identification:  # fmt: skip
    """Identify Eq. 46 for ``vehicle`` (its mass, inertia, geometry, rotor inertia and v0 are taken as
    known) from ``fit_data``; ``validation`` (another manoeuvre) gives the prediction metrics.
    ``domain_m_s`` fixes where the airspeed regressors saturate (horizontal, vertical; m/s) instead of
    deriving it from the fit data (``measure.domain_limits``)."""
    fit_data.check(vehicle.n_rotors)
    if validation is not None:
        validation.check(vehicle.n_rotors)
    raw = replace(vehicle, coefficients={}, domain_airspeed_m_s=1e9, domain_vertical_airspeed_m_s=1e9)
    vh_max, vz_max = domain_m_s or domain_limits(equation_error(fit_data, raw, raw.as_array(), rate_hz))
    p = replace(raw, domain_airspeed_m_s=vh_max, domain_vertical_airspeed_m_s=vz_max).as_array()
    ee = equation_error(fit_data, raw, p, rate_hz)
    val = equation_error(validation, raw, p, rate_hz) if validation is not None else None
    axes: dict[str, AxisResult] = {}
    coefs: dict[str, float] = {}
    ci: dict[str, float] = {}
    for k in range(6):
        r = _axis(k, ee, val, f_enter)
        axes[r.axis] = r
        coefs.update(zip(r.names, r.theta, strict=True))
        ci.update(zip(r.names, r.ci95, strict=True))
    return Identification(axes=axes, coefficients=coefs, ci95=ci, domain=domain_table(ee, vehicle.mixing),
                          domain_airspeed_m_s=vh_max, domain_vertical_airspeed_m_s=vz_max,
                          n_fit=int(ee.use.sum()), n_validation=int(val.use.sum()) if val is not None else 0,
                          exclusions=fit_data.exclusions,
                          wind_assumed_ned=tuple(float(w) for w in fit_data.wind_ned),  # type: ignore[arg-type]
                          sources=(fit_data.source,) + ((validation.source,) if validation is not None else ()),
                          data=(ee, val))
