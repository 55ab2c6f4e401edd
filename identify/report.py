"""The identification's outputs: the identified vehicle, the report in words, the figures.

:func:`identified_vehicle` puts the estimates into the vehicle (its model replaced; its truth, mass,
geometry and rotors kept), with the fit, the identified domain and the wind assumed in
``[model.info]``; :func:`format_report` is the text a user reads (Tables 1, 3, 4 and 5 of the paper
for this vehicle, and what could not be identified, never printed as a fact); :func:`plot_fit` draws
measured against modelled force and moment per axis on both manoeuvres (the paper's Figure 12).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from identify.measure import EquationError
from identify.pipeline import Identification
from vehicle.params import COEFFICIENT_NAMES, VehicleParams
from vehicle.rotor_model import AXIS_NAMES, AXIS_OF

#: Paper Table 1 (R^2 %) and Table 4 (validation TIC, NRMSE), for the report's comparison column.
PAPER = {"x": (99.5, 0.1676, 0.0750), "y": (88.7, 0.1574, 0.0809), "z": (95.0, 0.0060, 0.0250),
         "l": (92.0, 0.1409, 0.0568), "m": (94.4, 0.1370, 0.0512), "n": (54.3, 0.4588, 0.1675)}  # fmt: skip
UNITS = {"x": "N", "y": "N", "z": "N", "l": "N*m", "m": "N*m", "n": "N*m"}


def identified_vehicle(base: VehicleParams, ident: Identification, command: str = "") -> VehicleParams:
    """``base`` with the identified Eq. 46 (coefficients in SI, 95 % half-widths, domain) and its report."""
    info: dict[str, Any] = {
        "source": command or "windseek identify",
        "data": list(ident.sources),
        "wind_assumed_ned_m_s": list(ident.wind_assumed_ned),
        "samples_fit": ident.n_fit,
        "samples_validation": ident.n_validation,
        "excluded": list(ident.exclusions),
        "fit": {a: {k: v for k, v in m.items() if v is not None} for a, m in ident.table().items()},
        "domain_p5_p95": ident.domain,
        "not_identified": {a: r.not_identified for a, r in ident.axes.items() if r.not_identified},
        # The fitting flight's accelerometer bias (m/s^2, FRD, with its 95 % half-width): not the vehicle's.
        "accelerometer_bias_m_s2": {a: [r.bias[0] / base.mass_kg, r.bias[1] / base.mass_kg]
                                    for a, r in ident.axes.items() if r.bias is not None},
    }
    return replace(base, coefficients=dict(ident.coefficients), ci95=dict(ident.ci95),
                   domain_airspeed_m_s=ident.domain_airspeed_m_s,
                   domain_vertical_airspeed_m_s=ident.domain_vertical_airspeed_m_s, model_info=info)  # fmt: skip


def format_report(ident: Identification, vehicle_name: str) -> str:
    """The identification in words and tables (see the module docstring)."""
    out = [f"System identification of {vehicle_name} (Eq. 46; {ident.n_fit} fitting samples, "
           f"{ident.n_validation} validation samples)"]  # fmt: skip
    for s in ident.sources:
        out.append(f"  data: {s}")
    w = ident.wind_assumed_ned
    out.append(f"  wind assumed: [{w[0]:g}, {w[1]:g}, {w[2]:g}] m/s NED (airspeed = ground velocity - wind)")
    for e in ident.exclusions:
        out.append(f"  excluded: {e}")
    out.append("")
    out.append("axis   R^2 %   s^2 (SI)     fit TIC  fit NRMSE  val TIC  val NRMSE   paper: R^2 %  val TIC  NRMSE")
    for a, r in ident.axes.items():
        vt = f"{r.val_tic:8.4f}" if r.val_tic is not None else "     n/a"
        vn = f"{r.val_nrmse:9.4f}" if r.val_nrmse is not None else "      n/a"
        p = PAPER[a]
        out.append(f"  {a.upper()}  {r.r2_pct:7.2f}  {r.s2:10.4g}  {r.fit_tic:8.4f}  {r.fit_nrmse:9.4f}  {vt}  {vn}"
                   f"   {p[0]:12.1f}  {p[1]:7.4f}  {p[2]:.4f}")  # fmt: skip
    out.append("")
    out.append("estimates (SI) with 95 % intervals, corrected for coloured residuals:")
    for r in ident.axes.values():
        for n, th, ci in zip(r.names, r.theta, r.ci95, strict=True):
            out.append(f"  {n:10s} {th:+.5e} +- {ci:.2e}")
    biases = [(a, r.bias) for a, r in ident.axes.items() if r.bias is not None]
    if biases:
        out.append("  constant force fitted beside the model, not part of it (the flight's accelerometer bias times "
                   "the mass), N: " + ", ".join(f"{a.upper()} {b[0]:+.4f} +- {b[1]:.4f}" for a, b in biases))
    out.append("")
    out.append("not identified (never used by the model):")
    any_missing = False
    for a, r in ident.axes.items():
        for n, why in r.not_identified.items():
            if "crosses zero" in why or "not excited" in why or "collinear" in why or "zero" in why:
                out.append(f"  {a.upper()} {n}: {why}")
                any_missing = True
    if not any_missing:
        out.append("  (every chosen regressor is significant; unchosen candidates are listed in the vehicle file)")
    out.append("")
    out.append("identified domain (5th / 95th percentile, SI; paper Table 3):")
    for k, (lo, hi) in ident.domain.items():
        out.append(f"  {k:8s} {lo:+.4g} / {hi:+.4g}")
    out.append(f"  regressors saturate (tanh) at horizontal airspeed {ident.domain_airspeed_m_s:.2f} m/s, vertical "
               f"{ident.domain_vertical_airspeed_m_s:.2f} m/s")  # fmt: skip
    return "\n".join(out)


def plot_fit(path: Path | str, ident: Identification, fit_ee: EquationError, val_ee: EquationError | None) -> None:
    """Measured and modelled force and moment per axis on the fitting and the validation manoeuvre (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    theta = np.array([ident.coefficients.get(n, 0.0) for n in COEFFICIENT_NAMES])
    cols = [("fitting", fit_ee)] + ([("validation", val_ee)] if val_ee is not None else [])
    fig, axes = plt.subplots(6, len(cols), figsize=(7 * len(cols), 13), sharex="col", squeeze=False)
    for c, (title, ee) in enumerate(cols):
        for k in range(6):
            ax = axes[k, c]
            sel = k == AXIS_OF
            y = ee.X[:, sel] @ theta[sel]
            bias = ident.axes[AXIS_NAMES[k]].bias
            if bias is not None:  # the fitting flight's own; the validation's is its mean residual
                y = y + (bias[0] if title == "fitting" else float(np.mean(ee.z[ee.use, k] - y[ee.use])))
            ax.plot(ee.t, ee.z[:, k], lw=0.7, label="measured")
            ax.plot(ee.t, y, lw=0.7, label="model")
            ax.set_ylabel(f"{AXIS_NAMES[k].upper()} ({UNITS[AXIS_NAMES[k]]})")
            if k == 0:
                ax.set_title(f"{title} manoeuvre")
                ax.legend(loc="upper right")
        axes[-1, c].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
