"""Template: a source-seeking strategy (copy, rename, fill in).

A strategy is a plain, synchronous, deterministic state machine with no I/O: the runner (in-process
lockstep, or MAVSDK in real time) calls :meth:`reset` once and :meth:`update` at ``params.rate_hz``
(10 Hz) with what a real vehicle has, and flies the returned setpoint. This one flies upwind at the
search altitude until it detects the chemical, then declares the first detection point.

Register it (the strategy and its parameter class, here the common one)::

    mission.strategies.STRATEGIES["upwind-first-hit"] = UpwindFirstHit
    mission.strategies.params.PARAM_CLASSES["upwind-first-hit"] = CommonParams

Units SI, NED (altitude = -z above home), headings in rad (0 = north, clockwise).
"""

from __future__ import annotations

import math

import numpy as np

from mission.strategies.base import Observation, Setpoint, heading_vec
from mission.strategies.params import CommonParams


class UpwindFirstHit:
    """Fly upwind; declare where the chemical is first detected."""

    name = "upwind-first-hit"

    def reset(self, start_ned: np.ndarray, params: CommonParams, seed: int = 0) -> None:
        self.home = np.asarray(start_ned, dtype=float)
        self.p = params
        self.rng = np.random.default_rng(seed)  # any random choice must come from the seed
        self.declared: np.ndarray | None = None

    def update(self, obs: Observation) -> Setpoint:
        z = self.home[2] - self.p.altitude_m
        if self.declared is None and obs.detected and obs.chem_new:
            self.declared = np.array([obs.position_ned[0], obs.position_ned[1], z])
        if self.declared is not None:
            return Setpoint(position_ned=self.declared, done=True, declared_source_ned=self.declared,
                            confidence=0.5, state="declared")  # fmt: skip
        heading = obs.wind.upwind_rad if obs.wind is not None and math.isfinite(obs.wind.upwind_rad) else 0.0
        v = self.p.speed_m_s * heading_vec(heading)
        target = np.array([obs.position_ned[0] + v[0], obs.position_ned[1] + v[1], z])
        return Setpoint(position_ned=target, velocity_ned=np.array([v[0], v[1], 0.0]), yaw_rad=heading,
                        state="upwind")  # fmt: skip
