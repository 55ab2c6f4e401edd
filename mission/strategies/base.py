"""Strategy interface: observation in, setpoint out.

Conventions (the whole project's):
- SI units (m, s, rad, m/s); world frame NED (x north, y east, z down; altitude = -z);
  body frame FRD. Headings/yaw in rad, 0 = north, positive clockwise seen from above.
- WIND = AIR-MASS VELOCITY IN NED: a 5 m/s wind from the north is [-5, 0, 0]. "Upwind" is the
  direction opposite the air-mass velocity, so the upwind heading equals the meteorological
  from-direction (wind from the north -> fly north, heading 0).
- Docs and the command line use degrees and from-directions; code uses radians.

A strategy is a plain, synchronous, deterministic state machine with no I/O: the runner
(in-process lockstep, or a MAVSDK loop at 10-20 Hz built from MAVLink telemetry) builds an
:class:`Observation` from what a real vehicle has (position and velocity from its navigation
filter, the chemical sensor, the wind estimator) and sends the returned :class:`Setpoint` to
the autopilot. The runner holds no strategy logic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np


def wrap_pi(a: float) -> float:
    """Angle wrapped to [-pi, pi) (rad)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def heading_vec(heading_rad: float) -> np.ndarray:
    """Horizontal unit vector (north, east) of a heading (rad, 0 = north, clockwise)."""
    return np.array([math.cos(heading_rad), math.sin(heading_rad)])


def heading_of(v_ne: np.ndarray) -> float:
    """Heading (rad) of a horizontal (north, east) vector."""
    return math.atan2(float(v_ne[1]), float(v_ne[0]))


@dataclass(frozen=True)
class WindInfo:
    """What the strategy knows about the wind at one instant.

    wind_ned: air-mass velocity (3,), NED, m/s.
    cov_ned: its covariance (3, 3) (m/s)^2, or None when the source gives none (oracle).
    upwind_rad: low-pass filtered upwind heading (rad, = filtered from-direction), the paper's
        heading command for anemotaxis.
    upwind_sigma_rad: 1-sigma of the unfiltered direction (rad), from the covariance; 0 when
        unknown.
    """

    wind_ned: np.ndarray
    cov_ned: np.ndarray | None
    upwind_rad: float
    upwind_sigma_rad: float = 0.0

    @property
    def speed_m_s(self) -> float:
        """Horizontal wind speed, m/s."""
        return float(math.hypot(self.wind_ned[0], self.wind_ned[1]))


@dataclass(frozen=True)
class Observation:
    """Inputs of one strategy tick (everything a real vehicle has, nothing from the simulator's truth).

    t: time, s (any monotonic clock; the strategy only uses differences).
    position_ned: vehicle position (3,), m, NED, relative to the start/home point.
    velocity_ned: ground velocity (3,), m/s, NED.
    chem_mg_m3: latest chemical reading, mg/m^3 (0 below the detection limit).
    detected: the latest reading is at or above the sensor's detection limit.
    chem_new: a new chemical reading arrived since the previous tick (the sensor runs at its own
        rate; a stale reading must not be counted twice).
    wind: the wind information, or None in the ``none`` wind mode (pure chemotaxis).
    chem_t: time of the latest reading, s, on the clock of ``t`` (NaN: take ``t``). A reading can be
        older than the tick: over a lossy link the tick may pair an older reading with a newer time,
        and a decaying sensor read at the wrong time looks like a rise (a false hit).
    """

    t: float
    position_ned: np.ndarray
    velocity_ned: np.ndarray
    chem_mg_m3: float
    detected: bool
    chem_new: bool = True
    wind: WindInfo | None = None
    chem_t: float = math.nan


@dataclass
class Setpoint:
    """Output of one strategy tick, for ``offboard_setpoint`` (PX4 / MAVSDK offboard semantics).

    position_ned: position target (3,), m, NED, or None.
    velocity_ned: velocity (feed-forward when a position is given), (3,), m/s, NED, or None.
    yaw_rad: yaw target (rad, 0 = north) or None (keep).
    done: the search is over (declared or given up); the runner stops sending and lands/holds.
    declared_source_ned: the declared source position (3,), m, NED (None if not declared).
    confidence: confidence in the declaration, 0..1.
    state: name of the strategy's state, for logs.
    info: extra numbers for logs (strategy-specific).
    credible_radius_m: radius of the declared credible region about ``declared_source_ned``
        (horizontal, m; the probability is the strategy's, 90 % for infotaxis), NaN when the
        strategy states none.
    """

    position_ned: np.ndarray | None = None
    velocity_ned: np.ndarray | None = None
    yaw_rad: float | None = None
    done: bool = False
    declared_source_ned: np.ndarray | None = None
    confidence: float = 0.0
    state: str = ""
    info: dict[str, float] = field(default_factory=dict)
    credible_radius_m: float = math.nan


@runtime_checkable
class Strategy(Protocol):
    """A source-seeking strategy: a deterministic state machine, observation in, setpoint out."""

    name: str

    def reset(self, start_ned: np.ndarray, params: object, seed: int = 0) -> None:
        """Start a new search; ``start_ned`` is the home point on the ground (m, NED; altitudes
        are above it), ``params``
        (the strategy's parameter dataclass); ``seed`` seeds any randomized choice."""
        ...

    def update(self, obs: Observation) -> Setpoint:
        """One tick (call at 10-20 Hz): the setpoint to fly until the next tick."""
        ...
