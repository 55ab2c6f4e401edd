"""The SITL's parameters: the built-in autopilot's gains and flight settings, the geofence action,
and the simulation knobs (see :mod:`sitl.link.params` for the names and units).

Each parameter reads and writes one named thing of a narrow part (the autopilot's gains and
:class:`~sitl.autopilot.modes.FlightConfig`, the geofence, the pacing speed, the world's wind and
sensor noise); nothing here holds the whole link.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from sitl.autopilot.builtin import BuiltinAutopilot
from sitl.autopilot.controller import GAIN_NAMES
from sitl.link.geofence import Geofence
from sitl.link.params import Param
from sitl.world.world import World

FLIGHT_PARAMS = (  # PX4 name, FlightConfig field, range
    ("MIS_TAKEOFF_ALT", "takeoff_altitude_m", 0.5, 500.0),
    ("MPC_TKO_SPEED", "takeoff_speed_m_s", 0.1, 10.0),
    ("MPC_LAND_SPEED", "land_speed_m_s", 0.1, 5.0),
    ("MPC_XY_CRUISE", "cruise_speed_m_s", 0.1, 20.0),
    ("RTL_RETURN_ALT", "rtl_altitude_m", 0.0, 500.0),
    ("COM_OF_LOSS_T", "offboard_timeout_s", 0.05, 60.0),
    ("COM_DISARM_LAND", "disarm_after_land_s", 0.0, 60.0),
)
NOISE_PARAMS = (  # name, sensor group, field, upper limit (1-sigma, SI)
    ("SIM_ACC_NOISE", "imu", "accel_noise_m_s2", 10.0),
    ("SIM_GYRO_NOISE", "imu", "gyro_noise_rad_s", 1.0),
    ("SIM_GPS_NOISE_H", "gnss", "pos_noise_h_m", 100.0),
    ("SIM_GPS_NOISE_V", "gnss", "pos_noise_v_m", 100.0),
    ("SIM_BARO_NOISE", "baro", "noise_pa", 1000.0),
    ("SIM_MAG_NOISE", "mag", "noise_gauss", 1.0),
    ("SIM_ESC_NOISE", "esc", "noise_rad_s", 1000.0),
)


class WorldKnobs:
    """The world's simulation-only knobs: the mean wind, the turbulence scale, the sensor noise."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.turb_scale = 1.0

    def _wind_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The built-in wind model's schedule velocities (K, 3) and turbulence samples (N, 3), m/s."""
        k = self.world.wind.kernel()
        if k is None:
            raise ValueError("this scenario's wind model has no SIM_WIND_* / SIM_TURB_SCALE knobs")
        return k.sched_vel, k.turb_uvw

    def wind_mean(self) -> np.ndarray:
        """Mean wind now at the model's reference height above the origin, m/s NED."""
        w = self.world
        return np.asarray(w.wind.mean(w.t, np.array([0.0, 0.0, -w.wind.reference_height_m])), dtype=float)

    def set_wind(self, axis: int, value: float) -> None:
        # The kernels read the schedule arrays by reference: overwriting every entry makes the
        # new mean wind hold from now on without rebuilding the field.
        sched_vel, _ = self._wind_arrays()
        sched_vel[:, axis] = value

    def set_turbulence(self, scale: float) -> None:
        _, uvw = self._wind_arrays()
        if uvw.size:
            if self.turb_scale == 0.0:
                raise ValueError("turbulence was scaled to 0 and cannot be restored")
            uvw *= scale / self.turb_scale
        self.turb_scale = float(scale)

    def noise(self, group: str, attr: str) -> float:
        return float(getattr(getattr(self.world.sensors.config, group), attr))

    def set_noise(self, group: str, attr: str, value: float) -> None:
        sens = self.world.sensors
        cfg = sens.config
        sens.config = replace(cfg, **{group: replace(getattr(cfg, group), **{attr: float(value)})})


def sitl_parameters(autopilot: BuiltinAutopilot, geofence: Geofence, knobs: WorldKnobs,
                    speed: Callable[[], float], set_speed: Callable[[float], None]) -> list[Param]:  # fmt: skip
    """The SITL's parameter list, in its fixed order (indices are stable across runs)."""
    params: list[Param] = []
    for g in GAIN_NAMES:
        params.append(Param(f"CTL_{g.upper()}"[:16], lambda g=g: autopilot.gain(g),
                            lambda v, g=g: autopilot.set_gain(g, v), 0.0, 1e4))  # fmt: skip
    cfg = autopilot.fc.config
    for name, attr, lo, hi in FLIGHT_PARAMS:
        params.append(Param(name, lambda a=attr: getattr(cfg, a), lambda v, a=attr: setattr(cfg, a, float(v)), lo, hi))
    params.append(Param("GF_ACTION", lambda: float(geofence.action),
                        lambda v: setattr(geofence, "action", int(v)), 0, 4))  # fmt: skip
    params.append(Param("SIM_SPEED", speed, set_speed, 0.05, 1000.0))
    for i, axis in enumerate("NED"):
        params.append(Param(f"SIM_WIND_{axis}", lambda i=i: knobs.wind_mean()[i],
                            lambda v, i=i: knobs.set_wind(i, v), -60.0, 60.0))  # fmt: skip
    params.append(Param("SIM_TURB_SCALE", lambda: knobs.turb_scale, knobs.set_turbulence, 0.0, 10.0))
    for name, group, attr, hi in NOISE_PARAMS:
        params.append(Param(name, lambda g=group, a=attr: knobs.noise(g, a),
                            lambda v, g=group, a=attr: knobs.set_noise(g, a, v), 0.0, hi))  # fmt: skip
    params.append(Param("MAV_SYS_ID", lambda: 1.0, None, 1, 1))
    return params
