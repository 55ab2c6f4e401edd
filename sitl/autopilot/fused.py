"""The built-in autopilot's fused fast path: its rate-level controller and the world's physics
tick in one compiled loop (500 Hz lockstep at hundreds of times real time).

The boundary stays explicit: each tick computes the rotor command (rad/s) from the controller
(:func:`sitl.autopilot.controller.control`) and hands it to the world's own
:func:`sitl.world.kernel.physics_tick`, the same function an outside controller's commands go
through (:func:`sitl.world.kernel.advance_commanded`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from sitl.autopilot.controller import F_IDLE, SP_FLAGS, control
from sitl.world.kernel import FLAG_CRASHED, Obstacles, physics_tick
from sitl.world.wind.kernel import WindKernel, open_wind, urban_wind
from vehicle.params import P_WMIN


@njit(cache=True)
def advance_controlled(
    n: int, tick0: int, dt: float, x: np.ndarray, flags: np.ndarray, p: np.ndarray, crash_speed: float,
    imu_div: int, rows: np.ndarray, fb: np.ndarray, wk: WindKernel, obs: Obstacles,
    sp: np.ndarray, gains: np.ndarray, cs: np.ndarray, accel_sp: np.ndarray,
) -> int:  # fmt: skip
    """``n`` physics ticks from ``tick0`` flown by the controller on setpoint ``sp`` (held over
    the ticks): crashed -> rotors stopped, armed idle -> minimum speed and controller memory
    cleared, else the cascaded controller. Returns the truth rows written to ``rows``."""
    nrow = 0
    w_cmd = np.zeros(4)
    wind = np.empty(3)
    st, sv, lp, z0, il, to, ta, tr, uvw, uo, ugp, un, ve, wd, uwp, tm, vt, of, ht, bb = wk  # once: see wind.kernel
    idle = int(sp[SP_FLAGS]) == F_IDLE
    for k in range(n):
        tick = tick0 + k
        t = tick * dt
        if uo:
            wind[0], wind[1], wind[2] = urban_wind(t, x[0], x[1], x[2], to, ta, tr, uvw, ugp, un, ve, wd, uwp, tm, vt,
                                                   of, ht, bb, False)  # fmt: skip
        else:
            wind[0], wind[1], wind[2] = open_wind(t, x[0], x[1], x[2], st, sv, lp, z0, il, to, ta, tr, uvw, False)
        if flags[FLAG_CRASHED] != 0.0:
            w_cmd[:] = 0.0
        elif idle:
            w_cmd[:] = p[P_WMIN]
            cs[:] = 0.0
        else:
            w_cmd = control(x, sp, gains, cs, p, dt, accel_sp)
        nrow = physics_tick(tick, dt, x, w_cmd, wind, flags, p, crash_speed, imu_div, rows, nrow, fb, obs)
    return nrow
