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
from sitl.world.kernel import FLAG_CRASHED, physics_tick
from sitl.world.wind.kernel import WindKernel, wind_velocity
from vehicle.params import P_WMIN


@njit(cache=True)
def advance_controlled(
    n: int, tick0: int, dt: float, x: np.ndarray, flags: np.ndarray, p: np.ndarray, crash_speed: float,
    imu_div: int, rows: np.ndarray, fb: np.ndarray, wk: WindKernel,
    sp: np.ndarray, gains: np.ndarray, cs: np.ndarray, accel_sp: np.ndarray,
) -> int:  # fmt: skip
    """``n`` physics ticks from ``tick0`` flown by the controller on setpoint ``sp`` (held over
    the ticks): crashed -> rotors stopped, armed idle -> minimum speed and controller memory
    cleared, else the cascaded controller. Returns the truth rows written to ``rows``."""
    nrow = 0
    w_cmd = np.zeros(4)
    idle = int(sp[SP_FLAGS]) == F_IDLE
    for k in range(n):
        tick = tick0 + k
        wind = wind_velocity(tick * dt, x[0:3], wk)
        if flags[FLAG_CRASHED] != 0.0:
            w_cmd[:] = 0.0
        elif idle:
            w_cmd[:] = p[P_WMIN]
            cs[:] = 0.0
        else:
            w_cmd = control(x, sp, gains, cs, p, dt, accel_sp)
        nrow = physics_tick(tick, dt, x, w_cmd, wind, flags, p, crash_speed, imu_div, rows, nrow, fb)
    return nrow
