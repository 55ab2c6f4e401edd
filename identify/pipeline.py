"""The paper's system identification of Eq. 46 for any vehicle: step-wise regression, equation error,
coloured-residual intervals, fit and prediction metrics (paper Tables 1, 3, 4, 5).

Per axis (X, Y, Z, L, M, N): the candidates are every Eq. 46 term of that axis (the paper's model
structure, including the terms its regression dropped, Assumption 1's rate terms and a bias);
step-wise regression (F-to-enter and F-to-remove, :func:`identify.stepwise.stepwise`) chooses the
structure, then the regressors whose 95 % interval (corrected for coloured residuals) crosses zero are
removed one at a time and the rest refitted, as the paper did ("large standard errors and 95 %
confidence intervals crossing zero ... were removed"). Reported per axis: R^2 and s^2 on the fitting
manoeuvre (Table 1), Theil's inequality coefficient and the NRMSE on the fitting and on the
independent validation manoeuvre (Table 4), the estimates and their 95 % intervals (Table 5), and the
identified domain (Table 3). Candidates the manoeuvre did not excite are named, never fitted.

No bias terms: a flight's constant offsets are its sensors' (an accelerometer's turn-on bias), not the
vehicle's; the paper's regression found them small. Against thrust terms over a narrow rotor-speed
range a bias is also nearly collinear, so a fitted one would distort them.
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


def _axis(k: int, ee: EquationError, val: EquationError | None, f_enter: float) -> AxisResult:
    cand = [i for i in range(len(COEFFICIENT_NAMES)) if AXIS_OF[i] == k]
    names = [COEFFICIENT_NAMES[i] for i in cand]
    use = ee.use
    z = ee.z[use, k]
    X = ee.X[use][:, cand]
    sw = stepwise(z, X, names, f_enter=f_enter, f_remove=f_enter)
    not_identified = {ne.name: ne.reason for ne in sw.not_excited}
    cols = list(sw.indices)
    pr = prune_insignificant(z, X[:, cols], [names[i] for i in cols])
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
        yv = val.X[val.use][:, cand] @ full
        val_tic, val_nrmse = tic(zv, yv), nrmse(zv, yv)
    steps = tuple(f"{s.action} {s.name} (F {s.f_value:.3g}, R^2 {s.r_squared_pct:.2f} %)" for s in sw.steps)
    steps += tuple(f"remove {n} (95 % interval crosses zero)" for n in pr.removed)
    return AxisResult(axis=AXIS_NAMES[k], names=f.names, theta=tuple(float(x) for x in f.theta),
                      ci95=tuple(float(x) for x in f.ci95_halfwidth), r2_pct=float(f.r_squared_pct),
                      s2=float(f.s_squared), fit_tic=tic(z, y_fit), fit_nrmse=nrmse(z, y_fit), val_tic=val_tic,
                      val_nrmse=val_nrmse, not_identified=not_identified, steps=steps)  # fmt: skip


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
