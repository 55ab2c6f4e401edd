"""The mission's view of an autopilot: :class:`Vehicle` (commands and waits) and :class:`VehicleState`.

The one mission loop (:mod:`mission.loop`) flies every mission through this interface; two
adapters implement it: :class:`mission.runners.lockstep.LockstepVehicle` (the simulator in-process,
in lockstep, for batch evaluation) and :class:`mission.runners.mavsdk_vehicle.MavsdkVehicle` (any
MAVLink autopilot through MAVSDK, in real time).

Conventions: SI, NED positions relative to the autopilot's local origin, altitudes above home,
yaw in rad; ``t`` is vehicle time (the autopilot's clock, s), never wall time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np

#: MAV_LANDED_STATE values the mission reads.
LANDED_UNDEFINED, LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_TAKEOFF, LANDED_LANDING = 0, 1, 2, 3, 4


@dataclass
class VehicleState:
    """The newest picture of the vehicle, all from the vehicle itself.

    t: vehicle time of the newest stamped telemetry, s (NaN before any).
    pos / vel: the autopilot's navigation estimate, m / m/s NED (pos None before the first).
    obs_pos / obs_vel: what the strategy observes (the autopilot's estimate over MAVLink; the raw
        GNSS fix in the lockstep adapter, with its noise and latency), m / m/s NED.
    yaw: heading, rad. armed, mode (PX4 mode name), landed (MAV_LANDED_STATE), crashed.
    chem / chem_seq / chem_t: the latest chemical reading (mg/m^3, 0 below the detection limit), how
        many readings have arrived, and the vehicle time of the latest one, s (NaN: not stamped).
    heartbeat_seq: heartbeats received (a fresh one tells the state is current after a link loss).
    boots: autopilot restarts seen: its boot clock went back (a rebooted autopilot starts disarmed, so
        a landing during a link loss that spans one was not its failsafe's).
    """

    t: float = math.nan
    pos: np.ndarray | None = None
    vel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    obs_pos: np.ndarray | None = None
    obs_vel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0
    armed: bool = False
    mode: str = ""
    landed: int = LANDED_UNDEFINED
    crashed: bool = False
    chem: float = 0.0
    chem_seq: int = 0
    chem_t: float = math.nan
    heartbeat_seq: int = 0
    boots: int = 0


class Wait(Enum):
    """How a wait ended."""

    OK = "ok"
    TIMEOUT = "timeout"
    LINK_LOST = "link-lost"


class CommandError(RuntimeError):
    """The autopilot refused or did not answer a command (the message says which and why)."""


class Vehicle(Protocol):
    """An autopilot the mission flies (see the module docstring)."""

    state: VehicleState

    def say(self, line: str) -> None:
        """Where the autopilot's and the runner's lines go."""
        ...

    async def wait(self, pred: Callable[[], bool], vehicle_s: float, wall_s: float | None = None) -> Wait:
        """Until ``pred()`` (checked at each new state), ``vehicle_s`` of vehicle time, ``wall_s`` of wall
        time (default: derived from ``vehicle_s``), or a link loss; never longer."""
        ...

    async def next_tick(self, t_next: float) -> Wait:
        """Until the vehicle clock reaches ``t_next`` (s) with a fresh state (the strategy tick)."""
        ...

    def link_lost(self) -> str | None:
        """Why the link counts as lost now (one line), or None."""
        ...

    async def await_link(self, grace_s: float) -> bool:
        """After a loss: wait up to ``grace_s`` wall seconds for the link and a fresh heartbeat."""
        ...

    async def arm(self) -> None: ...

    async def takeoff(self, altitude_m: float) -> None: ...

    async def start_offboard(self) -> None:
        """Enter offboard (a setpoint has been sent first, as PX4 requires)."""
        ...

    async def stop_offboard(self) -> None: ...

    def send_setpoint(self, pos: np.ndarray | None, vel: np.ndarray | None, yaw: float | None) -> None:
        """One offboard setpoint (m, m/s, rad, NED); cheap and synchronous (no waiting)."""
        ...

    async def hold(self) -> None: ...

    async def land(self) -> None: ...

    def publish(self, pairs: list[tuple[str, str]]) -> None:
        """Queue mission status for the wire (:mod:`wire.names` message name, JSON fields)."""
        ...
