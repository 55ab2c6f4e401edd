"""Wind: the mean wind (``steady``), Kaimal turbulence (``turbulence``), the numba sampling kernels
(``kernel``), the built-in field (``field``) and the model interface and registry (``model``).

Conventions: SI units; NED (the ground at z = 0, altitude = -z); wind = air-mass velocity in
NED (a 10 m/s wind *from* the north is ``[-10, 0, 0]``); directions are meteorological
from-directions in degrees. Every random process is seeded.
"""

from sitl.world.wind.field import WindField
from sitl.world.wind.kernel import WindKernel, wind_mean, wind_velocity, wind_velocity_many
from sitl.world.wind.model import WIND_MODELS, WindModel, make_wind, register_wind_model
from sitl.world.wind.steady import SteadyWind, WindChange, velocity_from_speed_direction
from sitl.world.wind.turbulence import IEC_I_REF, MIN_ADVECTION_SPEED_MS, KaimalTurbulence, kaimal_psd

__all__ = [
    "IEC_I_REF", "MIN_ADVECTION_SPEED_MS", "WIND_MODELS", "KaimalTurbulence", "SteadyWind", "WindChange",
    "WindField", "WindKernel", "WindModel", "kaimal_psd", "make_wind", "register_wind_model",
    "velocity_from_speed_direction", "wind_mean", "wind_velocity", "wind_velocity_many",
]
