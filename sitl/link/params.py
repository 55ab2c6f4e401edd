"""Parameter protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_SET with PARAM_VALUE echo.

Every parameter is a MAV_PARAM_TYPE_REAL32. Names (at most 16 characters):

- ``CTL_<GAIN>``: the controller gains and limits of :class:`sitl.autopilot.controller.ControllerGains`
  (e.g. ``CTL_POS_P_XY``), SI units and rad as documented there; live.
- PX4 names for the flight-mode settings of :class:`sitl.autopilot.flight_modes.FlightConfig`:
  ``MIS_TAKEOFF_ALT`` (m), ``MPC_TKO_SPEED``, ``MPC_LAND_SPEED``, ``MPC_XY_CRUISE`` (m/s),
  ``RTL_RETURN_ALT`` (m), ``COM_OF_LOSS_T`` (s, offboard loss timeout), ``COM_DISARM_LAND`` (s).
- ``GF_ACTION`` (0 none, 1 warning, 2 hold, 3 return, 4 land): what a geofence breach does.
- Simulation knobs (simulation only): ``SIM_SPEED`` (wall-clock speed factor), ``SIM_WIND_N``,
  ``SIM_WIND_E``, ``SIM_WIND_D`` (mean air-mass velocity NED, m/s, replaces the scenario's
  schedule from now on), ``SIM_TURB_SCALE`` (turbulence intensity, multiple of the scenario's),
  ``SIM_ACC_NOISE`` (m/s^2), ``SIM_GYRO_NOISE`` (rad/s), ``SIM_GPS_NOISE_H``, ``SIM_GPS_NOISE_V`` (m),
  ``SIM_BARO_NOISE`` (Pa), ``SIM_MAG_NOISE`` (gauss), ``SIM_ESC_NOISE`` (rad/s), 1-sigma.
- ``MAV_SYS_ID`` (read-only, 1).

A rejected PARAM_SET (unknown name, NaN, out of range) is answered with the unchanged value,
as PX4 does, and counted.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from sitl.autopilot.controller import GAIN_NAMES
from wire.dialect import mavlink

if TYPE_CHECKING:
    from sitl.link.runner import SitlLink


@dataclass
class Param:
    name: str
    get: Callable[[], float]
    set: Callable[[float], None] | None
    lo: float
    hi: float


class ParamTable:
    """The parameters of one SITL instance, in a fixed order (indices are stable)."""

    def __init__(self, sitl: SitlLink) -> None:
        self.sitl = sitl
        sim = sitl.sim
        params: list[Param] = []
        for g in GAIN_NAMES:
            params.append(Param(f"CTL_{g.upper()}"[:16], lambda g=g: sim.gain(g),
                                lambda v, g=g: sim.set_gain(g, v), 0.0, 1e4))  # fmt: skip
        cfg = sim.fc.config
        for name, attr, lo, hi in (
            ("MIS_TAKEOFF_ALT", "takeoff_altitude_m", 0.5, 500.0),
            ("MPC_TKO_SPEED", "takeoff_speed_m_s", 0.1, 10.0),
            ("MPC_LAND_SPEED", "land_speed_m_s", 0.1, 5.0),
            ("MPC_XY_CRUISE", "cruise_speed_m_s", 0.1, 20.0),
            ("RTL_RETURN_ALT", "rtl_altitude_m", 0.0, 500.0),
            ("COM_OF_LOSS_T", "offboard_timeout_s", 0.05, 60.0),
            ("COM_DISARM_LAND", "disarm_after_land_s", 0.0, 60.0),
        ):
            params.append(Param(name, lambda a=attr: getattr(cfg, a),
                                lambda v, a=attr: setattr(cfg, a, float(v)), lo, hi))  # fmt: skip
        params.append(Param("GF_ACTION", lambda: float(sitl.geofence.action),
                            lambda v: setattr(sitl.geofence, "action", int(v)), 0, 4))  # fmt: skip
        params.append(Param("SIM_SPEED", lambda: sitl.speed, sitl.set_speed, 0.05, 1000.0))
        for i, axis in enumerate("NED"):
            params.append(Param(f"SIM_WIND_{axis}", lambda i=i: self._wind_mean()[i],
                                lambda v, i=i: self._set_wind(i, v), -60.0, 60.0))  # fmt: skip
        self._turb_scale = 1.0
        params.append(Param("SIM_TURB_SCALE", lambda: self._turb_scale, self._set_turb, 0.0, 10.0))
        for name, group, attr, hi in (
            ("SIM_ACC_NOISE", "imu", "accel_noise_m_s2", 10.0),
            ("SIM_GYRO_NOISE", "imu", "gyro_noise_rad_s", 1.0),
            ("SIM_GPS_NOISE_H", "gnss", "pos_noise_h_m", 100.0),
            ("SIM_GPS_NOISE_V", "gnss", "pos_noise_v_m", 100.0),
            ("SIM_BARO_NOISE", "baro", "noise_pa", 1000.0),
            ("SIM_MAG_NOISE", "mag", "noise_gauss", 1.0),
            ("SIM_ESC_NOISE", "esc", "noise_rad_s", 1000.0),
        ):
            params.append(Param(name, lambda g=group, a=attr: getattr(getattr(sim.sensors.config, g), a),
                                lambda v, g=group, a=attr: self._set_noise(g, a, v), 0.0, hi))  # fmt: skip
        params.append(Param("MAV_SYS_ID", lambda: 1.0, None, 1, 1))
        self.params = params
        self.by_name = {p.name: i for i, p in enumerate(params)}

    # ------------------------------------------------------------------ simulation knobs
    def _wind_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        args = self.sitl.sim.wind.kernel_args()
        return args[1], args[8]  # schedule velocities (K, 3), turbulence samples (N, 3)

    def _wind_mean(self) -> np.ndarray:
        sim = self.sitl.sim
        return sim.wind.mean(sim.t, np.array([0.0, 0.0, -sim.scenario.wind.reference_height_m]))

    def _set_wind(self, axis: int, value: float) -> None:
        # The kernels read the schedule arrays by reference: overwriting every entry makes the
        # new mean wind hold from now on without rebuilding the field.
        sched_vel, _ = self._wind_arrays()
        sched_vel[:, axis] = value

    def _set_turb(self, scale: float) -> None:
        _, uvw = self._wind_arrays()
        if uvw.size:
            if self._turb_scale == 0.0:
                raise ValueError("turbulence was scaled to 0 and cannot be restored")
            uvw *= scale / self._turb_scale
        self._turb_scale = float(scale)

    def _set_noise(self, group: str, attr: str, value: float) -> None:
        sens = self.sitl.sim.sensors
        cfg = sens.config
        sens.config = replace(cfg, **{group: replace(getattr(cfg, group), **{attr: float(value)})})

    # ------------------------------------------------------------------ protocol
    def value_msg(self, index: int) -> object:
        p = self.params[index]
        return mavlink.MAVLink_param_value_message(
            p.name.encode(), float(p.get()), mavlink.MAV_PARAM_TYPE_REAL32, len(self.params), index
        )

    def lookup(self, name: str | bytes, index: int) -> int | None:
        if isinstance(name, bytes):
            name = name.decode("ascii", "replace")
        name = name.rstrip("\x00")
        if index >= 0:
            return index if index < len(self.params) else None
        return self.by_name.get(name)

    def set(self, index: int, value: float) -> bool:
        """Set a parameter; False (unchanged) if read-only, non-finite or out of range."""
        p = self.params[index]
        if p.set is None or not math.isfinite(value) or not (p.lo <= value <= p.hi):
            return False
        try:
            p.set(float(value))
        except ValueError:
            return False
        return True


class ParamProtocol:
    """PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET handlers on an endpoint."""

    def __init__(self, sitl: SitlLink, table: ParamTable) -> None:
        self.sitl = sitl
        self.table = table
        ep = sitl.endpoint
        ep.handlers["PARAM_REQUEST_LIST"] = self.on_request_list
        ep.handlers["PARAM_REQUEST_READ"] = self.on_request_read
        ep.handlers["PARAM_SET"] = self.on_set

    def on_request_list(self, msg: object, link: object) -> None:
        if not _for_us(msg):
            return
        self.sitl.endpoint.send_many([self.table.value_msg(i) for i in range(len(self.table.params))], link)

    def on_request_read(self, msg: object, link: object) -> None:
        if not _for_us(msg):
            return
        i = self.table.lookup(msg.param_id, int(msg.param_index))
        if i is None:
            self.sitl.endpoint.counters["params_unknown"] += 1
            return
        self.sitl.endpoint.send(self.table.value_msg(i), link)

    def on_set(self, msg: object, link: object) -> None:
        if not _for_us(msg):
            return
        i = self.table.lookup(msg.param_id, -1)
        if i is None:
            self.sitl.endpoint.counters["params_unknown"] += 1
            return
        if self.table.set(i, float(msg.param_value)):
            self.sitl.endpoint.send(self.table.value_msg(i))  # every link learns the new value
        else:
            self.sitl.endpoint.counters["params_rejected"] += 1
            self.sitl.endpoint.send(self.table.value_msg(i), link)


def _for_us(msg: object) -> bool:
    return getattr(msg, "target_system", 0) in (0, 1) and getattr(msg, "target_component", 0) in (0, 1)
