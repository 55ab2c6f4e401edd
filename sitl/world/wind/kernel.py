"""Numba kernels: the single implementation of wind sampling.

Every entry point takes its parameters as one :class:`WindKernel` named tuple, so a caller passes
the model's ``kernel()`` rather than a list of positional arrays, and a new built-in model adds
fields (and a branch) to the tuple. The per-sample functions :func:`open_wind` and
:func:`urban_wind` take the fields unpacked (why: below); the simulator's physics loops unpack the
tuple once and call one of them at every tick. Python code calls the model's methods (:mod:`sitl.world.wind.field`).

Units: m, s, m/s; positions and velocities NED; wind = air-mass velocity.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from urbanflow.sampling import urban_sample, urban_wind_at


class WindKernel(NamedTuple):
    """Parameters of the built-in wind model as the njit kernels read them.

    sched_t: (K+1,) change times, s; ``sched_t[0] = -inf`` (the initial wind).
    sched_vel: (K+1, 3) air-mass velocity at the reference height, m/s NED. Kernels read it by
        reference, so overwriting entries changes the wind from the next sample on (SIM_WIND_*).
    log_profile: True: logarithmic height profile of the horizontal components; False: uniform.
    z0: roughness length, m. inv_log_ref: 1 / ln(z_ref / z0).
    turb_on: turbulence on (``turb_uvw`` is (0, 3) when off).
    taylor: sample the turbulence as a frozen field advected by the mean wind (Taylor).
    turb_rate: sample rate of the periodic turbulence series, Hz.
    turb_uvw: (M, 3) u', v', w' series, m/s (u' along the mean wind, v' 90 deg to its right,
        w' down), periodic.
    urban_on: the mean wind is the solved urban field (:mod:`sitl.world.urban`) instead of the
        schedule and profile; then ``ugp``, ``u_n``, ``v_e``, ``w_d``, ``uwp``, ``tm`` and the building
        arrays ``verts``, ``offsets``, ``heights``, ``bbox`` are its arrays (empty otherwise), and the
        turbulence is scaled by the field's multiplier ``tm`` at the point (0 inside buildings).
    """

    sched_t: np.ndarray
    sched_vel: np.ndarray
    log_profile: bool
    z0: float
    inv_log_ref: float
    turb_on: bool
    taylor: bool
    turb_rate: float
    turb_uvw: np.ndarray
    urban_on: bool = False
    ugp: np.ndarray = np.zeros(5)
    u_n: np.ndarray = np.zeros((0, 0, 0))
    v_e: np.ndarray = np.zeros((0, 0, 0))
    w_d: np.ndarray = np.zeros((0, 0, 0))
    uwp: np.ndarray = np.zeros(6)
    tm: np.ndarray = np.zeros((0, 0, 0))
    verts: np.ndarray = np.zeros((0, 2))
    offsets: np.ndarray = np.zeros(1, dtype=np.int64)
    heights: np.ndarray = np.zeros(0)
    bbox: np.ndarray = np.zeros((0, 4))


@njit(cache=True)
def _schedule_index(t: float, sched_t: np.ndarray) -> int:
    """Index of the last schedule entry with time <= t (binary search; entry 0 is -inf)."""
    lo = 0
    hi = sched_t.shape[0] - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if sched_t[mid] <= t:
            lo = mid
        else:
            hi = mid - 1
    return lo


# Why the kernels unpack the tuple: numba copies a named tuple of arrays into every function it is
# passed to, with a reference-count update of each array, inlined or not, and a call with many array
# arguments costs the same way; with the urban arrays that was ~0.25 us per sample, five times the
# sample itself (a 1,000-puff plume update spent 80 % of its time there). So the per-sample
# functions take only the fields their model reads, every entry point unpacks the tuple once
# before its loop (in the order of the class) and picks the model once: the open-terrain loop never
# carries the urban arrays. The physics loops of :mod:`sitl.world.kernel` and
# :mod:`sitl.autopilot.fused` do the same.


@njit(cache=True, inline="always")
def _turbulence(
    t: float, x: float, y: float, rn: float, re: float, taylor: bool, turb_rate: float, uvw: np.ndarray,
) -> tuple[float, float, float, float, float]:  # fmt: skip
    """Turbulence at (x, y) m and time t s in a mean wind whose reference-height components are
    (rn, re) m/s: (u', v', w') m/s from the periodic series (frozen, Taylor) and the unit mean-wind
    axis (en, ee); u' is along the axis, v' 90 deg to its right, w' down."""
    # The frozen field is advected by the reference-height mean wind, one speed for all
    # heights, so that the turbulence stays a single field even under a log profile.
    speed = math.sqrt(rn * rn + re * re)
    if speed > 1e-9:
        en = rn / speed
        ee = re / speed
    else:
        en = 1.0  # calm: any axis works, north keeps the output defined
        ee = 0.0
    u_adv = max(speed, 1.0)
    tau = t
    if taylor:
        tau = t - (x * en + y * ee) / u_adv
    m = uvw.shape[0]
    s = tau * turb_rate
    s -= m * math.floor(s / m)  # periodic series: wrap into [0, m)
    i = int(s)
    if i >= m:  # s can round up to exactly m
        i = 0
    frac = s - i
    j = i + 1
    if j == m:
        j = 0
    up = uvw[i, 0] + frac * (uvw[j, 0] - uvw[i, 0])
    vp = uvw[i, 1] + frac * (uvw[j, 1] - uvw[i, 1])
    wp = uvw[i, 2] + frac * (uvw[j, 2] - uvw[i, 2])
    return up, vp, wp, en, ee


@njit(cache=True, inline="always")
def open_wind(
    t: float, x: float, y: float, z: float, sched_t: np.ndarray, sched_vel: np.ndarray, log_profile: bool,
    z0: float, inv_log_ref: float, turb_on: bool, taylor: bool, turb_rate: float, uvw: np.ndarray, mean_only: bool,
) -> tuple[float, float, float]:  # fmt: skip
    """Open-terrain air-mass velocity (m/s, NED) at NED (x, y, z) m, time t s: the schedule's wind at
    the reference height, the log profile, turbulence unless ``mean_only``. The arguments after
    ``z`` are the first nine fields of :class:`WindKernel`."""
    i = _schedule_index(t, sched_t)
    rn, re, md = sched_vel[i, 0], sched_vel[i, 1], sched_vel[i, 2]
    scale = 1.0
    if log_profile:
        # max() with z0 makes the wind vanish smoothly at/below z0 instead of log(0) = -inf.
        scale = math.log(max(-z, z0) / z0) * inv_log_ref
    mn, me = rn * scale, re * scale
    if mean_only or not turb_on:
        return mn, me, md
    up, vp, wp, en, ee = _turbulence(t, x, y, rn, re, taylor, turb_rate, uvw)
    # u' along e, v' along e rotated +90 deg about down, w' along NED down (the order of the sums is
    # the one of every recorded benchmark: results reproduce bit for bit).
    return mn + up * en - vp * ee, me + up * ee + vp * en, md + wp


@njit(cache=True, inline="always")
def urban_wind(
    t: float, x: float, y: float, z: float, turb_on: bool, taylor: bool, turb_rate: float, uvw: np.ndarray,
    ugp: np.ndarray, u_n: np.ndarray, v_e: np.ndarray, w_d: np.ndarray, uwp: np.ndarray, tm: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray, mean_only: bool,
) -> tuple[float, float, float]:  # fmt: skip
    """Urban air-mass velocity (m/s, NED) at NED (x, y, z) m, time t s: the solved field
    (:mod:`sitl.world.urban`) and the turbulence scaled by its multiplier at the point (stronger in
    wakes and canyons, weaker in sheltered air, none inside a building)."""
    if mean_only or not turb_on:
        return urban_wind_at(x, y, z, ugp, u_n, v_e, w_d, uwp, verts, offsets, heights, bbox)
    # The mean and the multiplier in one pass (one building test): a third of a puff's sample.
    mn, me, md, k = urban_sample(x, y, z, ugp, u_n, v_e, w_d, uwp, tm, verts, offsets, heights, bbox)
    up, vp, wp, en, ee = _turbulence(t, x, y, uwp[0] * uwp[4], uwp[0] * uwp[5], taylor, turb_rate, uvw)
    up, vp, wp = k * up, k * vp, k * wp
    return mn + up * en - vp * ee, me + up * ee + vp * en, md + wp


@njit(cache=True)
def _sample(t: float, pos: np.ndarray, w: WindKernel, mean_only: bool) -> np.ndarray:
    """Air-mass velocities (N, 3) m/s NED at NED points ``pos`` (N, 3) m, time t s."""
    st, sv, lp, z0, il, to, ta, tr, uvw, uo, ugp, un, ve, wd, uwp, tm, vt, of, ht, bb = w
    n = pos.shape[0]
    out = np.empty((n, 3))
    if uo:
        for k in range(n):
            out[k, 0], out[k, 1], out[k, 2] = urban_wind(t, pos[k, 0], pos[k, 1], pos[k, 2], to, ta, tr, uvw, ugp, un,
                                                         ve, wd, uwp, tm, vt, of, ht, bb, mean_only)  # fmt: skip
    else:
        for k in range(n):
            out[k, 0], out[k, 1], out[k, 2] = open_wind(t, pos[k, 0], pos[k, 1], pos[k, 2], st, sv, lp, z0, il, to, ta,
                                                        tr, uvw, mean_only)  # fmt: skip
    return out


@njit(cache=True)
def wind_mean(t: float, pos: np.ndarray, w: WindKernel) -> np.ndarray:
    """Mean (non-turbulent) air-mass velocity (3,) m/s NED at NED ``pos`` (3,) m, time ``t`` s."""
    return _sample(t, pos.reshape(1, 3), w, True)[0]


@njit(cache=True)
def wind_velocity(t: float, pos: np.ndarray, w: WindKernel) -> np.ndarray:
    """Air-mass velocity (3,) m/s NED (mean + turbulence) at NED ``pos`` (3,) m, time ``t`` s."""
    return _sample(t, pos.reshape(1, 3), w, False)[0]


@njit(cache=True)
def wind_velocity_many(t: float, pos_many: np.ndarray, w: WindKernel) -> np.ndarray:
    """Air-mass velocities (N, 3) m/s NED at NED points ``pos_many`` (N, 3) m, time ``t`` s."""
    return _sample(t, pos_many, w, False)
