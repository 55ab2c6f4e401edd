"""Which Eq. 46 terms a flight excited, before their estimates are believed; and whether the result can
sense the wind at all.

Step-wise regression chooses among candidates by partial F. It cannot tell a regressor that the flight
varied from one that carries only noise: in a hover the horizontal airspeed is the velocity estimate's
noise (a few cm/s) plus the wind nobody knows, and a regression of the forces on it finds "significant"
drag coefficients that mean nothing (the PX4 SITL hover log gave C_X_D = +156 +- 32 where the paper's
vehicle has -0.1). :func:`screen` therefore checks every term on the variables that drive it, by their
span (5th to 95th percentile) over the fitting samples (:data:`DRIVERS`, :data:`MIN_SPAN`):

    u, v, |V_h|   body airspeeds, horizontal airspeed   2 m/s (more than the unknown wind of calm air)
    w             vertical airspeed                     1 m/s
    p, q, r       body rates                            0.3 rad/s
    delta_a/e/r   roll, pitch, yaw virtual actuators    5 % of the median delta_t
    omega         mean rotor speed                      20 % of its median (the "v0" terms, linear in the
                                                        rotor speed, are collinear with the squared ones
                                                        while it stays put)

(C_Z_Tiz needs |V_h| too: at a hover its induced-velocity factor is 1, and it is C_Z_Tz.)

A term whose driver spans less is **not excited**: its column is zeroed and its axis identified again by
the pipeline's own per-axis estimation (:func:`identify.pipeline._axis`: step-wise regression, pruning,
metrics), and it is reported as not excited with the span it had. The thresholds are judgements, said
here; the paper's manoeuvre (:mod:`identify.design`) exceeds every one of them several times over.

:func:`wind_blind` says what the estimator would lack: a force term in X and in Y driven by the
airspeed (how the vehicle senses horizontal wind) and a thrust term.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from identify.measure import EquationError
from identify.pipeline import AxisResult, Identification, _axis
from vehicle.params import COEFFICIENT_NAMES, VehicleParams
from vehicle.rotor_model import AXIS_NAMES

#: Smallest 5th-95th percentile span of each driver (SI; the delta_* and omega ones relative, see above).
MIN_SPAN = {"u": 2.0, "v": 2.0, "|V_h|": 2.0, "w": 1.0, "p": 0.3, "q": 0.3, "r": 0.3,
            "delta_a": 0.05, "delta_e": 0.05, "delta_r": 0.05, "omega": 0.2}  # fmt: skip
RELATIVE = {"delta_a", "delta_e", "delta_r", "omega"}
#: The variables each term's regressor needs to vary (vehicle.rotor_model.model_regressors).
DRIVERS: dict[str, tuple[str, ...]] = {
    "C_X_Hmu": ("u",), "C_X_Hmu2": ("u",), "C_X_Hmuz": ("u", "w"), "C_X_Hmuv": ("u",), "C_X_D": ("u",),
    "C_Y_Hmu": ("v",), "C_Y_Hmu2": ("v",), "C_Y_Hmuz": ("v", "w"), "C_Y_Hmuv": ("v",), "C_Y_D": ("v",),
    "C_Z_T0": (), "C_Z_Tv": ("omega",), "C_Z_Tmu": ("|V_h|",), "C_Z_Tz": ("w",), "C_Z_Tmu2": ("|V_h|",),
    "C_Z_D": ("w",), "C_Z_Ti": ("|V_h|",), "C_Z_Tiz": ("w", "|V_h|"),
    "C_l_T0": ("delta_a",), "C_l_Tv": ("delta_a", "omega"), "C_l_Tmu": ("delta_a", "|V_h|"),
    "C_l_Tz": ("delta_a", "w"), "C_l_Rmu": ("u", "delta_r"), "C_l_Hmu": ("v",), "C_l_Hmu2": ("v",),
    "C_l_Hmuz": ("v", "w"), "C_l_Hmuv": ("v",), "C_l_p_dt": ("p",), "C_l_p": ("v", "p"),
    "C_m_T0": ("delta_e",), "C_m_Tv": ("delta_e", "omega"), "C_m_Tmu": ("delta_e", "|V_h|"),
    "C_m_Tz": ("delta_e", "w"), "C_m_Rmu": ("v", "delta_r"), "C_m_Hmu": ("u",), "C_m_Hmu2": ("u",),
    "C_m_Hmuz": ("u", "w"), "C_m_Hmuv": ("u",), "C_m_q_dt": ("q",), "C_m_q": ("v", "q"),
    "C_n_Q0": ("delta_r",), "C_n_Qv": ("delta_r", "omega"), "C_n_Qmu": ("delta_r", "|V_h|"),
    "C_n_Qz": ("delta_r", "w"), "C_n_Hmu": ("|V_h|",), "C_n_r_dt": ("r",), "C_n_r": ("r", "|V_h|"),
    "C_X_q_dt": ("q",), "C_Y_p_dt": ("p",),
}  # fmt: skip
assert set(DRIVERS) == set(COEFFICIENT_NAMES)
#: Force terms through which the estimator senses horizontal wind (the rotor drag and the fuselage's).
WIND_TERMS = {"x": ("C_X_Hmu", "C_X_Hmu2", "C_X_Hmuz", "C_X_Hmuv", "C_X_D"),
              "y": ("C_Y_Hmu", "C_Y_Hmu2", "C_Y_Hmuz", "C_Y_Hmuv", "C_Y_D")}  # fmt: skip
#: Thrust terms driven by the rotor speed alone (squared, or times v0 or the induced velocity).
THRUST_TERMS = ("C_Z_T0", "C_Z_Tv", "C_Z_Ti")


def spans(ee: EquationError, vehicle: VehicleParams) -> dict[str, float]:
    """The 5th-95th percentile span of every driver over the used samples (SI; relative ones divided by
    the median of delta_t, or of the mean rotor speed)."""
    u = ee.use
    a, r, w = ee.airspeed[u], ee.rates[u], ee.rotor_speeds[u]
    delta = (w**2) @ vehicle.mixing.T

    def span(x: np.ndarray) -> float:
        lo, hi = np.percentile(x, [5.0, 95.0])
        return float(hi - lo)

    dt = float(np.median(np.abs(delta[:, 0]))) or 1.0
    w_mean = w.mean(axis=1)
    out = {"u": span(a[:, 0]), "v": span(a[:, 1]), "|V_h|": span(np.hypot(a[:, 0], a[:, 1])), "w": span(a[:, 2]),
           "p": span(r[:, 0]), "q": span(r[:, 1]), "r": span(r[:, 2]), "delta_a": span(delta[:, 1]) / dt,
           "delta_e": span(delta[:, 2]) / dt, "delta_r": span(delta[:, 3]) / dt,
           "omega": span(w_mean) / (float(np.median(w_mean)) or 1.0)}  # fmt: skip
    return out


def not_excited(ee: EquationError, vehicle: VehicleParams) -> dict[str, str]:
    """Term -> why it is not excited (its drivers' spans below :data:`MIN_SPAN`)."""
    s = spans(ee, vehicle)
    out = {}
    for name, drivers in DRIVERS.items():
        low = [d for d in drivers if s[d] < MIN_SPAN[d]]
        if low:
            words = ", ".join(_span_words(d, s[d]) for d in low)
            out[name] = f"not excited: {words} over the fit"
    return out


def _span_words(d: str, value: float) -> str:
    if d in RELATIVE:
        ref = "median delta_t" if d.startswith("delta") else "its median"
        return f"{d} spans {value:.1%} of {ref} (needs {MIN_SPAN[d]:.0%})"
    unit = "rad/s" if d in ("p", "q", "r") else "m/s"
    return f"{d} spans {value:.2g} {unit} (needs {MIN_SPAN[d]:g})"


def screen(ident: Identification, vehicle: VehicleParams, f_enter: float = 4.0) -> Identification:
    """``ident`` with the terms the flight did not excite taken out and their axes identified again
    (unchanged when every term was excited). Needs ``ident.data`` (the equation-error data)."""
    if ident.data is None:
        raise ValueError("the identification carries no equation-error data to screen")
    ee, val = ident.data
    dull = not_excited(ee, vehicle)
    if not dull:
        return ident
    cols = [COEFFICIENT_NAMES.index(n) for n in dull]
    X = ee.X.copy()
    X[:, cols] = 0.0
    ee0 = replace(ee, X=X)
    axes: dict[str, AxisResult] = {}
    for k, a in enumerate(AXIS_NAMES):
        r = ident.axes[a]
        if any(AXIS_NAMES["XYZlmn".index(n[2])] == a for n in dull):
            r = _axis(k, ee0, val, f_enter)
            reasons = {n: dull.get(n, why) for n, why in r.not_identified.items()}
            r = replace(r, not_identified=reasons)
        axes[a] = r
    coefs = {n: th for r in axes.values() for n, th in zip(r.names, r.theta, strict=True)}
    ci = {n: c for r in axes.values() for n, c in zip(r.names, r.ci95, strict=True)}
    return replace(ident, axes=axes, coefficients=coefs, ci95=ci)


def wind_blind(ident: Identification) -> list[str]:
    """What the identified model lacks to estimate the wind (empty: nothing): an airspeed force term
    in X and in Y, and a thrust term (:data:`THRUST_TERMS`)."""
    out = [f"no {a.upper()} force term driven by the airspeed ({', '.join(WIND_TERMS[a])})"
           for a in ("x", "y") if not set(WIND_TERMS[a]) & set(ident.coefficients)]  # fmt: skip
    if not set(THRUST_TERMS) & set(ident.coefficients):
        out.append(f"no thrust term ({', '.join(THRUST_TERMS)})")
    return out
