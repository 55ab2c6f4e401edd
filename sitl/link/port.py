"""What the SITL's protocol handlers may use of the vehicle: :class:`AutopilotPort`.

Each handler (commands, offboard, mission, parameters, data-link failsafe) gets the endpoint
(to register for messages, send replies and count) and this narrow view of the built-in
autopilot, never the whole link or simulation. Units SI, NED; time = simulation seconds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sitl.autopilot.flight_modes import FlightController
from sitl.world.sensors import HomeConfig


@dataclass
class AutopilotPort:
    """The built-in autopilot as the MAVLink handlers see it.

    fc: the autopilot's command surface (arm, take-off, modes, mission, offboard setpoints).
    clock: simulation time now, s.
    position: the vehicle's position (its navigation estimate; the truth here), m NED.
    attitude: the vehicle's attitude quaternion [w, x, y, z], body FRD -> NED.
    home: the geodetic origin of the local NED frame (lat, lon deg, alt m AMSL).
    mission_changed: call after the mission or its current item changed (MISSION_CURRENT goes out).
    """

    fc: FlightController
    clock: Callable[[], float]
    position: Callable[[], np.ndarray]
    attitude: Callable[[], np.ndarray]
    home: HomeConfig
    mission_changed: Callable[[], None]

    def home_amsl(self) -> float:
        """Home altitude AMSL, m (the origin's altitude minus the home point's NED down)."""
        return self.home.alt_m - float(self.fc.home[2])
