"""Which samples of the re-run estimate are trusted, and the wind figures computed from them alone.

A sample of the estimate is not trusted (and is neither in the figures nor plotted as the wind) when

- it is within the first ``settle_s`` of its airborne segment: the filter starts with no wind prior
  and the take-off transient (ground contact, spin-up, the climb) is not in the force model (the
  PX4 SITL hover log reads -59.8 m/s vertical wind at take-off);
- the log has positions and the vehicle is less than ``min_height_m`` above the segment's ground
  level (the lowest point of the segment and of the 30 s before it): touchdown comes before the
  landed state, and in ground contact or ground effect the rotor model does not hold.

When no sample is trusted there is no figure, and :func:`figures` says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimator.direction import from_direction_deg
from review.estimate import EstimatorTrack
from review.flight import FlightData, Series

#: How far before a segment's start its ground level is looked for [s] (the in-air state may come late).
GROUND_LOOKBACK_S = 30.0


@dataclass
class Trust:
    """Per track row: trusted or not, and how many rows each rule left out."""

    ok: np.ndarray
    settling: int
    near_ground: int


def trust_mask(fd: FlightData, track: EstimatorTrack, settle_s: float, min_height_m: float) -> Trust:
    """The trusted rows of ``track`` (see the module docstring)."""
    settled = track.t >= track.segment_start + settle_s
    low = np.zeros(len(track.t), dtype=bool)
    if len(fd.position) and min_height_m > 0 and len(track.t):
        pt, pz = fd.position.t, fd.position.v[:, 2]
        z = np.interp(track.t, pt, pz)
        ground: dict[float, float] = {}
        segs = fd.airborne_segments()
        for s0 in np.unique(track.segment_start):  # a filter span's start: in one airborne segment
            a, b = next(((a, b) for a, b in segs if a <= s0 <= b), (s0, s0))
            i, j = np.searchsorted(pt, a - GROUND_LOOKBACK_S), np.searchsorted(pt, b, side="right")
            ground[float(s0)] = float(np.nanmax(pz[i:j])) if j > i else math.nan
        z_ground = np.array([ground[float(a)] for a in track.segment_start])
        low = (z_ground - z) < min_height_m  # NaN (no position there): kept
    return Trust(ok=settled & ~low, settling=int((~settled).sum()), near_ground=int((settled & low).sum()))


def _interp(src: Series, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of (N, k) rows at t, and the mask of t inside the source's span."""
    if not len(src):
        return np.full((len(t), src.v.shape[1]), np.nan), np.zeros(len(t), dtype=bool)
    inside = (t >= src.t[0]) & (t <= src.t[-1])
    out = np.column_stack([np.interp(t, src.t, src.v[:, k]) for k in range(src.v.shape[1])])
    return out, inside


def _rmse(d: np.ndarray) -> dict[str, float | None]:
    """RMS per NED axis and horizontal of differences (N, 3) [m/s]; NaN entries left out."""
    out: dict[str, float | None] = {}
    for k, a in enumerate("NED"):
        col = d[:, k][np.isfinite(d[:, k])]
        out[a] = round(float(np.sqrt(np.mean(col**2))), 3) if len(col) else None
    h = np.hypot(d[:, 0], d[:, 1])
    h = h[np.isfinite(h)]
    out["horizontal"] = round(float(np.sqrt(np.mean(h**2))), 3) if len(h) else None
    return out


def _nanmean_cols(a: np.ndarray) -> np.ndarray:
    """Column means over the finite entries (NaN for a column without any), without numpy's warning."""
    fin = np.isfinite(a)
    n = fin.sum(axis=0)
    total = np.where(fin, a, 0.0).sum(axis=0)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def _r(v: Any, nd: int = 3) -> list[float | None]:
    return [None if not math.isfinite(float(x)) else round(float(x), nd) for x in v]


def no_figure_reason(fd: FlightData, track: EstimatorTrack, trust: Trust, settle_s: float, min_height_m: float) -> str:
    """Why no sample qualified for a figure."""
    air = sum(b - a for a, b in fd.airborne_segments())
    n = len(track.t)
    parts = [f"{trust.settling} of {n} estimate sample(s) in the first {settle_s:g} s of their segment "
             f"({air:.1f} s airborne in all)"]  # fmt: skip
    if trust.near_ground:
        parts.append(f"{trust.near_ground} less than {min_height_m:g} m above the ground")
    return "no estimate sample qualifies: " + ", ".join(parts)


def figures(fd: FlightData, track: EstimatorTrack, trust: Trust) -> dict[str, Any]:
    """Mean and spread of the trusted estimate, and its comparison with the truth and the autopilot."""
    ok = trust.ok
    w, t = track.wind[ok], track.t[ok]
    mean = w.mean(axis=0)
    s: dict[str, Any] = {
        "samples_scored": int(ok.sum()),
        "wind_mean_ned_ms": _r(mean),
        "wind_std_ned_ms": _r(w.std(axis=0)),
        "wind_speed_mean_ms": round(float(math.hypot(mean[0], mean[1])), 3),
        "wind_from_mean_deg": round(float(from_direction_deg(mean[0], mean[1])), 1),
    }
    ref, inside = _interp(fd.truth_wind, t)
    s["rmse_vs_truth_ms"] = _rmse(w[inside] - ref[inside]) if inside.any() else None
    ref, inside = _interp(fd.autopilot_wind, t)
    s["diff_vs_autopilot_ms"] = _rmse(w[inside] - ref[inside]) if inside.any() else None
    s["autopilot_wind_mean_ned_ms"] = None
    if inside.any():
        am = _nanmean_cols(ref[inside])
        s["autopilot_wind_mean_ned_ms"] = _r(am)
        s["autopilot_wind_speed_mean_ms"] = round(float(math.hypot(am[0], am[1])), 3)
        s["autopilot_wind_from_mean_deg"] = round(float(from_direction_deg(am[0], am[1])), 1)
        s["mean_diff_vs_autopilot_ned_ms"] = _r(mean - am)
    return s


__all__ = ["Trust", "figures", "no_figure_reason", "trust_mask"]
