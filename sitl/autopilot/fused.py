"""The built-in autopilot's fused fast path: its rate-level controller and the world's physics
tick in one compiled loop (500 Hz lockstep at hundreds of times real time).

The boundary stays explicit: each tick computes the rotor command (rad/s) from the controller
(:func:`sitl.autopilot.controller.control`) and hands it to the world's own
:func:`sitl.world.kernel.physics_tick`, the same function an outside controller's commands go
through (:func:`sitl.world.kernel.advance_commanded`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from sitl.autopilot.controller import F_IDLE, SP_FLAGS, control, control_work
from sitl.world.dynamics import physics_work
from sitl.world.kernel import FLAG_CRASHED, Obstacles, physics_tick, sample_winds
from sitl.world.wind.kernel import WindKernel
from vehicle.params import MAX_ROTORS, P_NROT, P_WMAX, P_WMIN


@njit(cache=True)
def advance_controlled(
    n: int, tick0: int, dt: float, x: np.ndarray, flags: np.ndarray, p: np.ndarray, crash_speed: float,
    imu_div: int, rows: np.ndarray, fb: np.ndarray, wk: WindKernel, obs: Obstacles,
    sp: np.ndarray, gains: np.ndarray, cs: np.ndarray, accel_sp: np.ndarray, dw2: np.ndarray, dw2_tick0: int,
) -> int:  # fmt: skip
    """``n`` physics ticks from ``tick0`` flown by the controller on setpoint ``sp`` (held over
    the ticks): crashed -> rotors stopped, armed idle -> minimum speed and controller memory
    cleared, else the cascaded controller. Returns the truth rows written to ``rows``.

    ``dw2`` (K, MAX_ROTORS): an excitation added to the controller's squared rotor-speed commands,
    row ``tick - dw2_tick0`` at each tick inside it (rad^2/s^2; the system identification's
    multisine, injected at the motor commands inside the closed loop as the paper does); the sum is
    limited to the rotor speed range. K = 0: none."""
    nrow = 0
    # The scratch of the physics tick and the controller, allocated once per control period (a tick allocates
    # nothing).
    w_cmd = np.zeros(MAX_ROTORS)
    winds = np.zeros((1 + MAX_ROTORS, 3))
    wrk = physics_work()
    cwk = control_work()
    st, sv, lp, z0, il, to, ta, tr, uvw, uo, ugp, un, ve, wd, uwp, tm, vt, of, ht, bb = wk  # once: see wind.kernel
    idle = int(sp[SP_FLAGS]) == F_IDLE
    n_rot = int(p[P_NROT])
    for k in range(n):
        tick = tick0 + k
        sample_winds(tick * dt, x, p, winds, wrk.R, st, sv, lp, z0, il, to, ta, tr, uvw, uo, ugp, un, ve, wd, uwp, tm,
                     vt, of, ht, bb)  # fmt: skip
        if flags[FLAG_CRASHED] != 0.0:
            w_cmd[:] = 0.0
        elif idle:
            w_cmd[:n_rot] = p[P_WMIN]
            cs[:] = 0.0
        else:
            control(x, sp, gains, cs, p, dt, accel_sp, w_cmd, cwk)
            j = tick - dw2_tick0
            if 0 <= j < dw2.shape[0]:
                lo2 = p[P_WMIN] * p[P_WMIN]
                for i in range(n_rot):
                    w_cmd[i] = min(math.sqrt(max(w_cmd[i] * w_cmd[i] + dw2[j, i], lo2)), p[P_WMAX])
        nrow = physics_tick(tick, dt, x, w_cmd, winds, flags, p, crash_speed, imu_div, rows, nrow, fb, obs, wrk)
    return nrow
