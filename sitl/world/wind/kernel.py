"""Numba kernels: the single implementation of wind sampling.

Every sampler takes its parameters as one :class:`WindKernel` named tuple, so the kernels read
``w.sched_vel`` rather than the ninth positional argument, and a new built-in model adds fields
(and a branch) instead of a new argument list. The simulator calls :func:`wind_velocity` from
its own njit physics loop; Python code calls the model's methods (:mod:`sitl.world.wind.field`).

Units: m, s, m/s; positions and velocities NED; wind = air-mass velocity.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from sitl.world.urban.sampling import urban_multiplier_at, urban_wind_at


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


# inline="always" on the per-tick helpers: a call passes the WindKernel tuple (about twenty arrays)
# by value; inlined into the fused loop the simulator runs 12-15 % faster (benchmarks/README.md).
@njit(cache=True, inline="always")
def _mean_components(t: float, z: float, w: WindKernel) -> tuple[float, float, float, float, float]:
    """(mean n, e, d at height -z; reference-height n, e) in m/s NED at time t."""
    i = _schedule_index(t, w.sched_t)
    vn = w.sched_vel[i, 0]
    ve = w.sched_vel[i, 1]
    vd = w.sched_vel[i, 2]
    scale = 1.0
    if w.log_profile:
        h = -z
        # max() with z0 makes the wind vanish smoothly at/below z0 instead of log(0) = -inf.
        scale = math.log(max(h, w.z0) / w.z0) * w.inv_log_ref
    return vn * scale, ve * scale, vd, vn, ve


@njit(cache=True, inline="always")
def _urban_mean(x: float, y: float, z: float, w: WindKernel) -> tuple[float, float, float, float, float]:
    """Like :func:`_mean_components` for the urban field: (mean n, e, d; reference-height n, e)."""
    mn, me, md = urban_wind_at(x, y, z, w.ugp, w.u_n, w.v_e, w.w_d, w.uwp, w.verts, w.offsets, w.heights, w.bbox)
    return mn, me, md, w.uwp[0] * w.uwp[4], w.uwp[0] * w.uwp[5]


@njit(cache=True, inline="always")
def _wind_components(t: float, x: float, y: float, z: float, w: WindKernel) -> tuple[float, float, float]:
    """Air-mass velocity (m/s, NED) at NED point (x, y, z) and time t, as three floats."""
    if w.urban_on:
        mn, me, md, rn, re = _urban_mean(x, y, z, w)
    else:
        mn, me, md, rn, re = _mean_components(t, z, w)
    if not w.turb_on:
        return mn, me, md
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
    if w.taylor:
        tau = t - (x * en + y * ee) / u_adv
    uvw = w.turb_uvw
    m = uvw.shape[0]
    s = tau * w.turb_rate
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
    if w.urban_on:  # stronger in wakes and canyons, weaker in sheltered air, none inside a building
        m = urban_multiplier_at(x, y, z, w.ugp, w.tm, w.verts, w.offsets, w.heights, w.bbox)
        up, vp, wp = m * up, m * vp, m * wp
    # u' along e, v' along e rotated +90 deg about down, w' along NED down.
    return mn + up * en - vp * ee, me + up * ee + vp * en, md + wp


@njit(cache=True)
def wind_mean(t: float, pos: np.ndarray, w: WindKernel) -> np.ndarray:
    """Mean (non-turbulent) air-mass velocity (3,) m/s NED at NED ``pos`` (3,) m, time ``t`` s."""
    if w.urban_on:
        mn, me, md, _, _ = _urban_mean(pos[0], pos[1], pos[2], w)
    else:
        mn, me, md, _, _ = _mean_components(t, pos[2], w)
    out = np.empty(3)
    out[0] = mn
    out[1] = me
    out[2] = md
    return out


@njit(cache=True, inline="always")
def wind_velocity(t: float, pos: np.ndarray, w: WindKernel) -> np.ndarray:
    """Air-mass velocity (3,) m/s NED (mean + turbulence) at NED ``pos`` (3,) m, time ``t`` s."""
    vn, ve, vd = _wind_components(t, pos[0], pos[1], pos[2], w)
    out = np.empty(3)
    out[0] = vn
    out[1] = ve
    out[2] = vd
    return out


@njit(cache=True)
def wind_velocity_many(t: float, pos_many: np.ndarray, w: WindKernel) -> np.ndarray:
    """Air-mass velocities (N, 3) m/s NED at NED points ``pos_many`` (N, 3) m, time ``t`` s."""
    n = pos_many.shape[0]
    out = np.empty((n, 3))
    for k in range(n):
        vn, ve, vd = _wind_components(t, pos_many[k, 0], pos_many[k, 1], pos_many[k, 2], w)
        out[k, 0] = vn
        out[k, 1] = ve
        out[k, 2] = vd
    return out
