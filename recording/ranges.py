"""Value ranges of the time series plots, fitted to the data a recorder sent.

A plot opened on its full data range is often unreadable: the estimator's first seconds carry
+-10 m/s of uncertainty and a touchdown spikes the vertical wind. :func:`fit_ranges` takes robust
percentiles of the series that matter in each plot (truth, estimate, raw, and the +-2 sigma band's
typical edges) over the flight and pads them, so the early wide band and the spikes run off the edge
instead of flattening the rest.
The padding is small (a tenth of the span each side): the viewer labels a value axis only when its
unit steps are about 20 px apart, and the wind plots are ~110 px tall in a 1000 px window. It then
labels whole units only: a wind plot is widened to hold two whole units at least (a range of
-0.6..0.6 m/s showed a single label, "0").
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from recording.style import AXES


class _HasValues(Protocol):
    c_range_mg_m3: tuple[float, float]
    chem_threshold: float | None

    def values(self, entity: str) -> tuple[np.ndarray, np.ndarray]: ...


def _collect(rec: _HasValues, entities: tuple[str, ...], t0: float, t1: float) -> np.ndarray:
    parts = []
    for e in entities:
        t, v = rec.values(e)
        sel = (t >= t0) & (t <= t1) & np.isfinite(v)
        parts.append(v[sel])
    return np.concatenate(parts) if parts else np.zeros(0)


def robust_range(v: np.ndarray, q: tuple[float, float] = (1.0, 99.0), pad: float = 0.1,
                 min_span: float = 1.0) -> tuple[float, float] | None:  # fmt: skip
    """The ``q`` percentiles of ``v`` widened by ``pad`` of their span on each side (at least ``min_span``)."""
    if not len(v):
        return None
    lo, hi = (float(x) for x in np.percentile(v, q))
    span = max(hi - lo, min_span)
    mid = 0.5 * (lo + hi)
    half = 0.5 * span * (1.0 + 2.0 * pad)
    return round(mid - half, 3), round(mid + half, 3)


#: Plots of the flight's own series: key -> (entities, smallest span of the value axis).
FLIGHT_RANGES: dict[str, tuple[tuple[str, ...], float]] = {
    "altitude": (("flight/altitude/vehicle", "flight/altitude/gps"), 2.0),
    "velocity": (tuple(f"flight/velocity/{a}" for a in AXES), 2.0),
    "attitude": (tuple(f"flight/attitude/{a}" for a in ("roll", "pitch", "yaw")), 20.0),
    "voltage": (("flight/battery/voltage",), 1.0),
    "current": (("flight/battery/current",), 2.0),
    "remaining": (("flight/battery/remaining",), 10.0),
    "gps": (("flight/gps/fix", "flight/gps/satellites"), 4.0),
}


def two_units(r: tuple[float, float]) -> tuple[float, float]:
    """``r`` widened to hold two consecutive whole numbers (two labels on the viewer's value axis)."""
    lo, hi = r
    mid = math.floor(0.5 * (lo + hi))
    # k, k + 1 about the middle, whichever pair widens the range least (none: it has two already)
    k = min((mid - 1, mid), key=lambda j: max(lo - (j - 0.1), 0.0) + max((j + 1.1) - hi, 0.0))
    if lo <= k and k + 1 <= hi:
        return r
    return round(min(lo, k - 0.1), 3), round(max(hi, k + 1.1), 3)


def fit_ranges(rec: _HasValues, t_range: tuple[float, float]) -> dict[str, tuple[float, float]]:
    """Plot key (:data:`recording.layout.PLOTS`) -> (low, high) over ``t_range`` [s] (plots without data: none)."""
    t0, t1 = t_range
    out: dict[str, tuple[float, float]] = {}
    for a in AXES:
        r = robust_range(_collect(rec, (f"wind/{a}/truth", f"wind/{a}/estimate", f"wind/{a}/autopilot"), t0, t1))
        band = _collect(rec, (f"wind/{a}/band",), t0, t1)
        if r is not None and len(band):
            # The band's typical edges (its rows alternate between them: the quartiles of all rows are
            # about the medians of the lower and the upper edge) stay on the plot, so a band wider than
            # the data reads as a band and not as a filled plot; early, wider ones still run off.
            lo, hi = (float(x) for x in np.percentile(band, (25.0, 75.0)))
            pad = 0.1 * (hi - lo)
            r = (round(min(r[0], lo - pad), 3), round(max(r[1], hi + pad), 3))
        if r is not None:
            out[a] = two_units(r)
    sp = _collect(rec, ("wind/speed/truth", "wind/speed/filtered", "wind/speed/raw", "wind/speed/autopilot"), t0, t1)
    r = robust_range(sp)
    if r is not None:
        out["speed"] = (max(0.0, r[0]), r[1])
    dirs = ("wind/direction/truth", "wind/direction/filtered", "wind/direction/raw", "wind/direction/autopilot")
    r = robust_range(_collect(rec, dirs, t0, t1), min_span=20.0)
    if r is not None:
        out["direction"] = r
    chem = _collect(rec, ("chem/log10",), t0, t1)
    if len(chem):
        floor = math.log10(rec.c_range_mg_m3[0])
        top = max(float(chem.max()), floor + 1.0)
        if rec.chem_threshold is not None and rec.chem_threshold > 0:
            top = max(top, math.log10(rec.chem_threshold) + 0.5)
        out["chem"] = (round(floor - 0.15, 3), round(top + 0.25, 3))
    rot = _collect(rec, tuple(f"rotors/{i}" for i in range(1, 5)), t0, t1)
    rot = rot[rot > 50.0]  # in flight (on the ground the rotors stand still)
    r = robust_range(rot, q=(0.5, 99.5), pad=0.1, min_span=20.0)
    if r is not None:
        out["rotors"] = r
    for key, (entities, span) in FLIGHT_RANGES.items():
        r = robust_range(_collect(rec, entities, t0, t1), q=(0.5, 99.5), min_span=span)
        if r is not None:
            out[key] = r
    return out


__all__ = ["FLIGHT_RANGES", "fit_ranges", "robust_range", "two_units"]
