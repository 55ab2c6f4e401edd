"""A setpoint that travels toward a target at a speed, with acceleration limits (NED, SI)."""

from __future__ import annotations

import math

import numpy as np


def vec_norm(v: np.ndarray) -> float:
    """Euclidean norm of a small vector; the mode logic calls this a few times per 50 Hz tick, where
    ``np.linalg.norm``'s dispatch (~3 us a call) was a measurable part of the simulator's speed."""
    return math.sqrt(float(v.dot(v)))


class Trajectory:
    """A setpoint that travels from its current point toward a target at a speed, with
    acceleration and deceleration limits, so waypoints are approached without overshoot."""

    def __init__(self, start: np.ndarray) -> None:
        self.pos = np.array(start, dtype=float)
        self.target = self.pos.copy()
        self.speed = 0.0
        self.vel = np.zeros(3)
        self.acc = np.zeros(3)

    def retarget(self, target: np.ndarray) -> None:
        self.target = np.array(target, dtype=float)

    def reset(self, pos: np.ndarray) -> None:
        self.pos = np.array(pos, dtype=float)
        self.target = self.pos.copy()
        self.speed = 0.0
        self.vel[:] = 0.0
        self.acc[:] = 0.0

    def update(self, dt: float, cruise: float, accel: float, vehicle_pos: np.ndarray, lead: float) -> None:
        d = self.target - self.pos
        dist = vec_norm(d)
        if dist < 1e-6:
            self.pos = self.target.copy()
            self.speed = 0.0
            self.vel[:] = 0.0
            self.acc[:] = 0.0
            return
        v_allow = min(cruise, math.sqrt(2.0 * accel * dist))
        if vec_norm(self.pos - vehicle_pos) > lead:
            v_allow = min(v_allow, 0.5 * cruise)
        prev = self.speed
        self.speed = max(min(self.speed + accel * dt, v_allow), 0.0)
        step = min(self.speed * dt, dist)
        u = d / dist
        self.pos = self.pos + u * step
        self.vel = u * self.speed
        self.acc = u * (self.speed - prev) / dt
