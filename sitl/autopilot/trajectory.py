"""A setpoint that travels toward a target at a speed, with acceleration limits (NED, SI).

The moving setpoint's state is one array (:attr:`Trajectory.state`: position, target, velocity, acceleration,
speed) advanced by a compiled step (:func:`advance_setpoint`) that the mode logic calls once per slow tick, and
that also writes the controller's setpoint (:func:`trajectory_setpoint`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from sitl.autopilot.controller import SP_ACC, SP_POS, SP_VEL, SP_YAW

#: Slices of :attr:`Trajectory.state`: position, target (NED, m), velocity (m/s), acceleration (m/s^2); speed (m/s).
TR_POS, TR_TARGET, TR_VEL, TR_ACC, TR_SPEED = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), 12


def vec_norm(v: np.ndarray) -> float:
    """Euclidean norm of a small vector; the mode logic calls this a few times per 50 Hz tick, where
    ``np.linalg.norm``'s dispatch (~3 us a call) was a measurable part of the simulator's speed."""
    return math.sqrt(float(v.dot(v)))


@njit(cache=True)
def advance_setpoint(st: np.ndarray, dt: float, cruise: float, accel: float, vehicle_pos: np.ndarray,
                     lead: float) -> None:  # fmt: skip
    """One step of ``dt`` [s] of the moving setpoint ``st`` (see :attr:`Trajectory.state`) toward its target at up
    to ``cruise`` [m/s] with acceleration ``accel`` [m/s^2], at half speed while more than ``lead`` [m] ahead of
    ``vehicle_pos`` (NED, m). The norms are numpy's ``v.dot(v)`` (the same BLAS call), the rest numpy's order."""
    d = st[3:6] - st[0:3]
    dist = math.sqrt(d.dot(d))
    if dist < 1e-6:
        st[0:3] = st[3:6]
        st[6:13] = 0.0
        return
    v_allow = min(cruise, math.sqrt(2.0 * accel * dist))
    e = st[0:3] - vehicle_pos
    if math.sqrt(e.dot(e)) > lead:
        v_allow = min(v_allow, 0.5 * cruise)
    prev = st[12]
    speed = max(min(prev + accel * dt, v_allow), 0.0)
    step = min(speed * dt, dist)
    for i in range(3):
        u = d[i] / dist
        st[i] = st[i] + u * step
        st[6 + i] = u * speed
        st[9 + i] = u * (speed - prev) / dt
    st[12] = speed


@njit(cache=True)
def trajectory_setpoint(st: np.ndarray, sp: np.ndarray, dt: float, cruise: float, accel: float,
                        vehicle_pos: np.ndarray, lead: float, yaw: float) -> None:  # fmt: skip
    """:func:`advance_setpoint`, then the controller's setpoint ``sp`` cleared and given the moving setpoint's
    position, velocity and acceleration and the yaw ``yaw`` [rad] (the flags are the caller's)."""
    advance_setpoint(st, dt, cruise, accel, vehicle_pos, lead)
    sp[:] = 0.0
    sp[SP_POS:SP_POS + 3] = st[0:3]
    sp[SP_VEL:SP_VEL + 3] = st[6:9]
    sp[SP_ACC:SP_ACC + 3] = st[9:12]
    sp[SP_YAW] = yaw


@njit(cache=True)
def waypoint_reached(st: np.ndarray, vehicle_pos: np.ndarray, radius: float) -> bool:
    """The vehicle (NED, m) within ``radius`` [m] of the moving setpoint's target and the setpoint arrived there
    (within 1 mm) (the norms as :func:`vec_norm`)."""
    e = vehicle_pos - st[3:6]
    d = st[0:3] - st[3:6]
    return math.sqrt(e.dot(e)) <= radius and math.sqrt(d.dot(d)) < 1e-3


class Trajectory:
    """A setpoint that travels from its current point toward a target at a speed, with acceleration and
    deceleration limits, so waypoints are approached without overshoot. ``pos``, ``target``, ``vel`` and ``acc``
    are views of :attr:`state` (assigning one writes its values in)."""

    def __init__(self, start: np.ndarray) -> None:
        self.state = np.zeros(13)
        self.pos = start
        self.target = self.pos

    pos = property(lambda self: self.state[TR_POS], lambda self, v: self.state.__setitem__(TR_POS, v),
                   doc="Moving setpoint, NED, m.")  # fmt: skip
    target = property(lambda self: self.state[TR_TARGET], lambda self, v: self.state.__setitem__(TR_TARGET, v),
                      doc="Where it travels to, NED, m.")  # fmt: skip
    vel = property(lambda self: self.state[TR_VEL], doc="Its velocity, NED, m/s.")
    acc = property(lambda self: self.state[TR_ACC], doc="Its acceleration, NED, m/s^2.")

    @property
    def speed(self) -> float:
        """Its speed along the way, m/s."""
        return float(self.state[TR_SPEED])

    def retarget(self, target: np.ndarray) -> None:
        self.target = target

    def reset(self, pos: np.ndarray) -> None:
        self.pos = pos
        self.target = self.pos
        self.state[TR_VEL.start:] = 0.0

    def update(self, dt: float, cruise: float, accel: float, vehicle_pos: np.ndarray, lead: float) -> None:
        advance_setpoint(self.state, dt, cruise, accel, vehicle_pos, lead)
