"""The world's physics loop (numba): one implementation of a physics tick, and the loop that
holds externally commanded rotor speeds over many ticks.

A tick samples the wind at the vehicle and at each rotor hub (held over the step; the hubs only
for the blade-element truth, which feels the wind at each rotor), integrates the rigid body with
RK4 (:func:`sitl.world.dynamics.rk4_step`), resolves the ground, flags a crash, and every
``imu_div`` ticks writes one truth row (the IMU sample instant). The built-in autopilot's fused
loop (:mod:`sitl.autopilot.fused`) calls the same :func:`physics_tick`, so a vehicle flown by an
outside controller and one flown by the built-in autopilot see the same physics bit for bit.

Truth row columns (``T_*``), recorded at every IMU sample instant: time (s), specific force
(FRD, m/s^2), body rates (FRD, rad/s), rotor speeds (rad/s, MAX_ROTORS slots, the vehicle's first),
position (NED, m), velocity (NED, m/s), attitude quaternion (body -> NED), wind at the vehicle's CG
(air-mass velocity NED, m/s), rotor command (rad/s, MAX_ROTORS slots).
``flags`` = [on_ground, crashed, largest touchdown speed (m/s), collisions].
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from sitl.world.dynamics import S_XN, PhysicsWork, physics_work, rk4_step
from sitl.world.wind.kernel import WindKernel, open_wind, urban_wind
from urbanflow.geometry import building_at
from vehicle.frames import quat_to_dcm_into
from vehicle.params import MAX_ROTORS, P_NROT, P_ROT0, P_TRUTH, TRUTH_BET

T_TIME = 0
T_SPECIFIC_FORCE = slice(1, 4)  # FRD, m/s^2
T_RATES = slice(4, 7)  # FRD, rad/s
T_ROTORS = slice(7, 7 + MAX_ROTORS)  # rad/s
T_POS = slice(15, 18)  # NED, m
T_VEL = slice(18, 21)  # NED, m/s
T_QUAT = slice(21, 25)  # body -> NED
T_WIND = slice(25, 28)  # air-mass velocity at the vehicle's CG, NED, m/s
T_ROTOR_CMD = slice(28, 28 + MAX_ROTORS)  # rad/s
N_TRUTH = 28 + MAX_ROTORS

FLAG_ON_GROUND, FLAG_CRASHED, FLAG_TOUCHDOWN_SPEED, FLAG_COLLISIONS = 0, 1, 2, 3


class Obstacles(NamedTuple):
    """Buildings as prisms (the layout of :class:`urbanflow.geometry.BuildingArrays`): footprint
    vertices (V, 2) NED m, per-building vertex offsets (B + 1,), roof heights (B,) m above ground,
    footprint boxes (B, 4). No buildings: empty arrays."""

    verts: np.ndarray
    offsets: np.ndarray
    heights: np.ndarray
    bbox: np.ndarray


NO_OBSTACLES = Obstacles(np.zeros((0, 2)), np.zeros(1, dtype=np.int64), np.zeros(0), np.zeros((0, 4)))


def compiled_entry(dispatcher: Any, args: tuple[Any, ...]) -> Callable[..., Any]:
    """The compiled function numba's ``dispatcher`` runs for arguments of the types of ``args`` (loaded from the cache
    or compiled now), to be called without the dispatcher's typing of every argument at every call (~3 us for the
    fused loop's 18 arguments, 24 arrays of them in the wind and obstacle tuples). Only for a call site whose argument
    types never change (a world's arrays and tuples, made once); the dispatcher itself if numba's internals differ."""
    try:
        sig = tuple(dispatcher.typeof_pyval(a) for a in args)
        if sig not in dispatcher.overloads:
            dispatcher.compile(sig)
        return dispatcher.overloads[sig].entry_point
    except (AttributeError, KeyError, TypeError):
        return dispatcher


@njit(cache=True, inline="always")  # into the fused loops: no per-tick call with the Obstacles tuple
def physics_tick(
    tick: int, dt: float, x: np.ndarray, w_cmd: np.ndarray, winds: np.ndarray, flags: np.ndarray,
    p: np.ndarray, crash_speed: float, imu_div: int, rows: np.ndarray, nrow: int, fb: np.ndarray,
    obs: Obstacles, wk: PhysicsWork,
) -> int:  # fmt: skip
    """One physics tick in place with the rotor command ``w_cmd`` (rad/s) and the winds ``winds``
    (1 + N, 3; NED, m/s: at the CG, then at each hub; see :func:`sample_winds`) held over it. Returns
    the number of truth rows written so far (``nrow`` + 0 or 1). A step that would end inside a
    building is a crash: the vehicle stays where it hit, stopped. ``wk``: the loop's scratch
    (:func:`sitl.world.dynamics.physics_work`, allocated once per loop)."""
    on_ground = flags[FLAG_ON_GROUND] != 0.0
    og, vtd = rk4_step(x, w_cmd, winds, p, dt, on_ground, fb, wk)
    xn = wk.stages[S_XN]
    if obs.heights.shape[0] > 0 and building_at(xn[0], xn[1], -xn[2], obs.verts, obs.offsets, obs.heights,
                                                obs.bbox) >= 0:  # fmt: skip
        xn[:] = x
        xn[3:6] = 0.0
        xn[10:13] = 0.0
        flags[FLAG_CRASHED] = 1.0
        flags[FLAG_COLLISIONS] += 1.0
    if tick % imu_div == 0:
        r = rows[nrow]
        r[0] = tick * dt
        r[1:4] = fb
        r[4:7] = x[10:13]
        r[7:15] = x[13:21]
        r[15:18] = x[0:3]
        r[18:21] = x[3:6]
        r[21:25] = x[6:10]
        r[25:28] = winds[0]
        r[28:36] = w_cmd
        nrow += 1
    x[:] = xn
    flags[FLAG_ON_GROUND] = 1.0 if og else 0.0
    if vtd > flags[FLAG_TOUCHDOWN_SPEED]:
        flags[FLAG_TOUCHDOWN_SPEED] = vtd
    if vtd > 0.0 and vtd > crash_speed:
        flags[FLAG_CRASHED] = 1.0
    return nrow


@njit(cache=True, inline="always")
def sample_winds(
    t: float, x: np.ndarray, p: np.ndarray, winds: np.ndarray, R: np.ndarray, st: np.ndarray, sv: np.ndarray,
    lp: bool, z0: float, il: float, to: bool, ta: bool, tr: float, uvw: np.ndarray, uo: bool, ugp: np.ndarray,
    un: np.ndarray, ve: np.ndarray, wd: np.ndarray, uwp: np.ndarray, tm: np.ndarray, vt: np.ndarray, of: np.ndarray,
    ht: np.ndarray, bb: np.ndarray,
) -> None:  # fmt: skip
    """The winds a tick holds, into ``winds`` (1 + N, 3), air-mass velocity NED m/s: row 0 at the CG
    (the truth rows' wind), rows 1..N at the rotor hubs (NED position + R r_i) when the truth is
    blade-element (the turbulence's gradients across the airframe act on it; ``R`` (3, 3) receives
    the attitude matrix body -> NED then). The arguments after
    ``winds`` are the :class:`WindKernel` fields, unpacked once by the caller (see wind.kernel)."""
    n = int(p[P_NROT]) if p[P_TRUTH] == TRUTH_BET else 0
    if n > 0:
        quat_to_dcm_into(x[6:10], R)
    for k in range(n + 1):
        px, py, pz = x[0], x[1], x[2]
        if k > 0:
            j = P_ROT0 + 4 * (k - 1)
            px += R[0, 0] * p[j] + R[0, 1] * p[j + 1] + R[0, 2] * p[j + 2]
            py += R[1, 0] * p[j] + R[1, 1] * p[j + 1] + R[1, 2] * p[j + 2]
            pz += R[2, 0] * p[j] + R[2, 1] * p[j + 1] + R[2, 2] * p[j + 2]
        if uo:
            winds[k, 0], winds[k, 1], winds[k, 2] = urban_wind(t, px, py, pz, to, ta, tr, uvw, ugp, un, ve, wd, uwp,
                                                               tm, vt, of, ht, bb, False)  # fmt: skip
        else:
            winds[k, 0], winds[k, 1], winds[k, 2] = open_wind(t, px, py, pz, st, sv, lp, z0, il, to, ta, tr, uvw,
                                                              False)  # fmt: skip


@njit(cache=True)
def advance_commanded(
    n: int, tick0: int, dt: float, x: np.ndarray, w_cmd: np.ndarray, flags: np.ndarray, p: np.ndarray,
    crash_speed: float, imu_div: int, rows: np.ndarray, fb: np.ndarray, wk: WindKernel, obs: Obstacles,
) -> int:  # fmt: skip
    """``n`` physics ticks from tick ``tick0`` holding the commanded rotor speeds ``w_cmd`` (rad/s);
    a crashed vehicle's rotors get zero. Returns the number of truth rows written to ``rows``."""
    nrow = 0
    stopped = np.zeros(MAX_ROTORS)
    winds = np.zeros((1 + MAX_ROTORS, 3))
    wrk = physics_work()
    st, sv, lp, z0, il, to, ta, tr, uvw, uo, ugp, un, ve, wd, uwp, tm, vt, of, ht, bb = wk  # once: see wind.kernel
    for k in range(n):
        tick = tick0 + k
        sample_winds(tick * dt, x, p, winds, wrk.R, st, sv, lp, z0, il, to, ta, tr, uvw, uo, ugp, un, ve, wd, uwp, tm,
                     vt, of, ht, bb)  # fmt: skip
        cmd = stopped if flags[FLAG_CRASHED] != 0.0 else w_cmd
        nrow = physics_tick(tick, dt, x, cmd, winds, flags, p, crash_speed, imu_div, rows, nrow, fb, obs, wrk)
    return nrow
