"""Sampling the solved urban field at points (numba): the mean wind and the turbulence multiplier.

The single implementation of sampling; the world's wind kernel calls :func:`urban_wind_at` and
:func:`urban_multiplier_at` from its own compiled loop. Layout of the arrays and the rules (log-law
vertical interpolation, zero inside buildings, the upstream profile outside the grid) are in
:mod:`urbanflow.field`. Light on purpose: numpy and numba only, no solver.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .geometry import building_at
from .parameterizations import log_speed


@njit(cache=True, inline="always")
def _level(fk: float, nk: int) -> tuple[int, int, float]:
    """(k0, k1, weight of k1) for a fractional index clamped to [0, nk - 1]."""
    fk = min(max(fk, 0.0), nk - 1.0)
    k0 = min(int(fk), max(nk - 2, 0))
    k1 = min(k0 + 1, nk - 1)
    return k0, k1, fk - k0


@njit(cache=True, inline="always")
def _bilinear(a: np.ndarray, i0: int, i1: int, ti: float, j0: int, j1: int, tj: float, k: int) -> float:
    """Bilinear value of ``a[:, :, k]`` between columns i0, i1 (weight ti) and j0, j1 (tj)."""
    c0 = a[i0, j0, k] * (1.0 - ti) + a[i1, j0, k] * ti
    c1 = a[i0, j1, k] * (1.0 - ti) + a[i1, j1, k] * ti
    return c0 * (1.0 - tj) + c1 * tj


@njit(cache=True)
def _trilinear(a: np.ndarray, fi: float, fj: float, fk: float) -> float:
    """Trilinear value of ``a`` at fractional indices, each clamped to the array's extent."""
    i0, i1, ti = _level(fi, a.shape[0])
    j0, j1, tj = _level(fj, a.shape[1])
    k0, k1, tk = _level(fk, a.shape[2])
    return (1.0 - tk) * _bilinear(a, i0, i1, ti, j0, j1, tj, k0) + tk * _bilinear(a, i0, i1, ti, j0, j1, tj, k1)


@njit(cache=True, inline="always")
def _log_weights(h: float, fk: float, nk: int, dz: float, wp: np.ndarray) -> tuple[int, int, float, float]:
    """(k0, k1, w0, w1): vertical weights for the horizontal components between cell-centre
    levels, interpolating u / U_log(h) linearly and multiplying by U_log(h). The upstream profile
    is then reproduced exactly at every height, and below the first centre (or above the last)
    the value follows the log law instead of staying constant."""
    k0, k1, tk = _level(fk, nk)
    u_h = log_speed(h, wp[0], wp[1], wp[2], wp[3])
    u0 = log_speed((k0 + 0.5) * dz, wp[0], wp[1], wp[2], wp[3])
    u1 = log_speed((k1 + 0.5) * dz, wp[0], wp[1], wp[2], wp[3])
    if u0 <= 1e-9 or u1 <= 1e-9 or wp[0] <= 0.0:  # level at/below z0 (or calm): plain linear
        return k0, k1, 1.0 - tk, tk
    return k0, k1, (1.0 - tk) * u_h / u0, tk * u_h / u1  # clamped outside: tk is 0 or 1


#: Where a point is (:func:`_locate`): not finite, inside a building, outside the grid, in the grid.
NOT_FINITE, IN_BUILDING, OUTSIDE, IN_GRID = 0, 1, 2, 3


@njit(cache=True, inline="always")
def _locate(
    x: float, y: float, z: float, gp: np.ndarray, nx: int, ny: int, nz: int, verts: np.ndarray,
    offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> tuple[int, float, float, float]:  # fmt: skip
    """(where, fx, fy, fh): the one place the sampling rules decide where NED point (x, y, z) m is
    (one building test), and its fractional face indices (cells nx, ny, nz; ``gp`` as below)."""
    h = -z
    fx, fy, fh = (x - gp[0]) / gp[2], (y - gp[1]) / gp[3], h / gp[4]
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return NOT_FINITE, fx, fy, fh
    if building_at(x, y, h, verts, offsets, heights, bbox) >= 0:
        return IN_BUILDING, fx, fy, fh
    if fx < 0.0 or fx > nx or fy < 0.0 or fy > ny or fh > nz or h < 0.0:
        return OUTSIDE, fx, fy, fh
    return IN_GRID, fx, fy, fh


@njit(cache=True, inline="always")
def mean_in_grid(
    fx: float, fy: float, fh: float, h: float, dz: float, u_n: np.ndarray, v_e: np.ndarray, w_d: np.ndarray,
    wp: np.ndarray,
) -> tuple[float, float, float]:  # fmt: skip
    """Mean air-mass velocity (north, east, down) m/s at fractional face indices inside the grid."""
    nx, ny, nz = w_d.shape[0], w_d.shape[1], w_d.shape[2] - 1
    # Column indices shared by the three staggered grids: faces (fx, fy), centres (fx/fy - 0.5).
    if_0, if_1, tif = _level(fx, nx + 1)
    ic_0, ic_1, tic = _level(fx - 0.5, nx)
    jf_0, jf_1, tjf = _level(fy, ny + 1)
    jc_0, jc_1, tjc = _level(fy - 0.5, ny)
    k0, k1, w0, w1 = _log_weights(h, fh - 0.5, nz, dz, wp)
    un = w0 * _bilinear(u_n, if_0, if_1, tif, jc_0, jc_1, tjc, k0) + w1 * _bilinear(
        u_n, if_0, if_1, tif, jc_0, jc_1, tjc, k1
    )
    ve = w0 * _bilinear(v_e, ic_0, ic_1, tic, jf_0, jf_1, tjf, k0) + w1 * _bilinear(
        v_e, ic_0, ic_1, tic, jf_0, jf_1, tjf, k1
    )
    kw0, kw1, tkw = _level(fh, nz + 1)
    wd = (1.0 - tkw) * _bilinear(w_d, ic_0, ic_1, tic, jc_0, jc_1, tjc, kw0) + tkw * _bilinear(
        w_d, ic_0, ic_1, tic, jc_0, jc_1, tjc, kw1
    )
    return un, ve, wd


@njit(cache=True, inline="always")
def urban_sample(
    x: float, y: float, z: float, gp: np.ndarray, u_n: np.ndarray, v_e: np.ndarray, w_d: np.ndarray,
    wp: np.ndarray, tm: np.ndarray, verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray,
    bbox: np.ndarray,
) -> tuple[float, float, float, float]:  # fmt: skip
    """(north, east, down) mean air-mass velocity m/s and the turbulence multiplier at NED point
    (x, y, z) m in one pass: one building test and one grid look-up for both (the plume samples
    every puff this way; :func:`urban_wind_at` and :func:`urban_multiplier_at` give one of them
    by the same rules). Inside a building: zeros; outside the grid: the upstream log profile and
    multiplier 1; a non-finite point: NaNs."""
    where, fx, fy, fh = _locate(x, y, z, gp, w_d.shape[0], w_d.shape[1], w_d.shape[2] - 1, verts, offsets, heights,
                                bbox)  # fmt: skip
    if where == NOT_FINITE:
        return math.nan, math.nan, math.nan, math.nan
    if where == IN_BUILDING:
        return 0.0, 0.0, 0.0, 0.0
    if where == OUTSIDE:
        sp = log_speed(-z, wp[0], wp[1], wp[2], wp[3])
        return sp * wp[4], sp * wp[5], 0.0, 1.0
    un, ve, wd = mean_in_grid(fx, fy, fh, -z, gp[4], u_n, v_e, w_d, wp)
    return un, ve, wd, _trilinear(tm, fx - 0.5, fy - 0.5, fh - 0.5)


@njit(cache=True)
def urban_wind_at(
    x: float, y: float, z: float, gp: np.ndarray, u_n: np.ndarray, v_e: np.ndarray, w_d: np.ndarray,
    wp: np.ndarray, verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> tuple[float, float, float]:
    """Mean air-mass velocity (north, east, down) m/s at NED point (x, y, z) m.

    ``gp`` = (x0, y0, dx, dy, dz), ``wp`` = (U_ref, z0, d, 1/ln((z_ref-d)/z0), e_n, e_e).
    A non-finite position gives NaN (and never an out-of-range read).
    """
    where, fx, fy, fh = _locate(x, y, z, gp, w_d.shape[0], w_d.shape[1], w_d.shape[2] - 1, verts, offsets, heights,
                                bbox)  # fmt: skip
    if where == NOT_FINITE:
        return math.nan, math.nan, math.nan
    if where == IN_BUILDING:
        return 0.0, 0.0, 0.0
    if where == OUTSIDE:
        sp = log_speed(-z, wp[0], wp[1], wp[2], wp[3])
        return sp * wp[4], sp * wp[5], 0.0
    return mean_in_grid(fx, fy, fh, -z, gp[4], u_n, v_e, w_d, wp)


@njit(cache=True)
def urban_wind_mean(
    pos: np.ndarray, gp: np.ndarray, u_n: np.ndarray, v_e: np.ndarray, w_d: np.ndarray, wp: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> np.ndarray:
    """Mean air-mass velocity (3,) m/s NED at NED ``pos`` (3,) m; args: ``field.kernel_args()``."""
    out = np.empty(3)
    out[0], out[1], out[2] = urban_wind_at(pos[0], pos[1], pos[2], gp, u_n, v_e, w_d, wp, verts, offsets, heights, bbox)
    return out


@njit(cache=True)
def urban_wind_mean_many(
    points: np.ndarray, gp: np.ndarray, u_n: np.ndarray, v_e: np.ndarray, w_d: np.ndarray, wp: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> np.ndarray:
    """Mean air-mass velocities (N, 3) m/s NED at NED points (N, 3) m."""
    n = points.shape[0]
    out = np.empty((n, 3))
    for k in range(n):
        out[k, 0], out[k, 1], out[k, 2] = urban_wind_at(
            points[k, 0], points[k, 1], points[k, 2], gp, u_n, v_e, w_d, wp, verts, offsets, heights, bbox
        )
    return out


@njit(cache=True)
def urban_multiplier_at(x: float, y: float, z: float, gp: np.ndarray, tm: np.ndarray, verts: np.ndarray,
                        offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray) -> float:  # fmt: skip
    """Turbulence multiplier at one NED point (m): trilinear between cell centres, 0 inside buildings,
    1 outside the grid (the undisturbed flow), NaN for a non-finite point."""
    where, fx, fy, fh = _locate(x, y, z, gp, tm.shape[0], tm.shape[1], tm.shape[2], verts, offsets, heights, bbox)
    if where == NOT_FINITE:
        return math.nan
    if where == IN_BUILDING:
        return 0.0
    if where == OUTSIDE:
        return 1.0
    return _trilinear(tm, fx - 0.5, fy - 0.5, fh - 0.5)


@njit(cache=True)
def urban_turbulence_multiplier_at(
    points: np.ndarray, gp: np.ndarray, tm: np.ndarray, wp: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> np.ndarray:
    """Turbulence multiplier (N,) at NED points (N, 3): trilinear between cell centres, 0 inside
    buildings, 1 outside the grid (the undisturbed flow)."""
    n = points.shape[0]
    out = np.empty(n)
    for k in range(n):
        out[k] = urban_multiplier_at(points[k, 0], points[k, 1], points[k, 2], gp, tm, verts, offsets, heights, bbox)
    return out
