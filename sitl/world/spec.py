"""What the world is made of: :class:`WorldSpec`, the one record :class:`~sitl.world.world.World` takes.

The vehicle file, the physics and slow-tick rates, the wind (steady part, turbulence, wind model and
its options), the vehicle's start, the sensors, the plume and the urban scene. Nothing of who flies
the vehicle (the autopilot's gains and flight settings) or of what it is asked to do (the route, the
duration): those go to whoever builds the autopilot and the mission. ``sitl.scenario`` parses a
scenario file and assembles this spec (:meth:`sitl.scenario.Scenario.world_spec`), so the world
never imports the scenario parser, and through it the autopilot.

Conventions: SI units, NED world, FRD body, wind = air-mass velocity NED; start yaw in degrees
(as in the scenario file).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from sitl.world.plume.setup import PlumeSetup
from sitl.world.sensors import SensorSuiteConfig
from sitl.world.wind import KaimalTurbulence, SteadyWind
from urbanflow.config import UrbanScene


@dataclass(frozen=True)
class Start:
    """The vehicle's initial state: position NED [m], heading [deg], on the ground or in the air."""

    position_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw_deg: float = 0.0
    airborne: bool = False


@dataclass(frozen=True)
class WorldSpec:
    """The world's own settings (see the module docstring).

    name: the scenario's name (labels only); seed: the default seed (``World(seed=...)`` overrides);
    vehicle: a vehicle name or file; physics_rate_hz: the physics step rate (RK4) [Hz];
    mode_rate_hz: the slow tick (the pilot's slow logic, low-rate sensors, plume) [Hz].
    """

    name: str = "world"
    seed: int = 0
    vehicle: str = "nasa-quad"
    physics_rate_hz: float = 500.0
    mode_rate_hz: float = 50.0
    wind: SteadyWind = field(default_factory=lambda: SteadyWind(velocity_ned=(0.0, 0.0, 0.0)))
    turbulence: KaimalTurbulence | None = None
    wind_model: str = "steady"  # a name in sitl.world.wind.model.WIND_MODELS
    wind_options: tuple[tuple[str, Any], ...] = ()  # the [wind.options] table, for the wind model
    start: Start = field(default_factory=Start)
    sensors: SensorSuiteConfig = field(default_factory=SensorSuiteConfig)
    plume: PlumeSetup | None = None
    urban: UrbanScene | None = None

    def with_seed(self, seed: int) -> WorldSpec:
        return replace(self, seed=int(seed))


__all__ = ["Start", "WorldSpec"]
