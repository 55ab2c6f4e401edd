"""Parameter protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_SET with PARAM_VALUE echo.

The table (:class:`ParamTable`) and the protocol (:class:`ParamProtocol`); which parameters the
SITL has is :mod:`sitl.link.sim_params`. Every parameter is a MAV_PARAM_TYPE_REAL32. Names (at
most 16 characters):

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
from dataclasses import dataclass
from typing import Any

from sitl.link.endpoint import Endpoint
from wire.dialect import mavlink


@dataclass
class Param:
    """One parameter: its name, how to read and write it (None: read-only), its allowed range."""

    name: str
    get: Callable[[], float]
    set: Callable[[float], None] | None
    lo: float
    hi: float


class ParamTable:
    """The parameters of one SITL instance, in a fixed order (indices are stable)."""

    def __init__(self, params: list[Param]) -> None:
        self.params: list[Param] = []
        self.by_name: dict[str, int] = {}
        for p in params:
            self.add(p)

    def add(self, p: Param) -> None:
        """Append a parameter (ValueError on a duplicate or a name longer than 16 characters)."""
        if p.name in self.by_name or len(p.name) > 16:
            raise ValueError(f"parameter {p.name!r}: duplicate or longer than 16 characters")
        self.by_name[p.name] = len(self.params)
        self.params.append(p)

    def value_msg(self, index: int) -> Any:
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

    def __init__(self, ep: Endpoint, table: ParamTable) -> None:
        self.ep = ep
        self.table = table
        ep.handlers["PARAM_REQUEST_LIST"] = self.on_request_list
        ep.handlers["PARAM_REQUEST_READ"] = self.on_request_read
        ep.handlers["PARAM_SET"] = self.on_set

    def on_request_list(self, msg: object, link: object) -> None:
        if not _for_us(msg):
            return
        self.ep.send_many([self.table.value_msg(i) for i in range(len(self.table.params))], link)

    def on_request_read(self, msg: object, link: object) -> None:
        if not _for_us(msg):
            return
        i = self.table.lookup(msg.param_id, int(msg.param_index))
        if i is None:
            self.ep.counters["params_unknown"] += 1
            return
        self.ep.send(self.table.value_msg(i), link)

    def on_set(self, msg: object, link: object) -> None:
        if not _for_us(msg):
            return
        i = self.table.lookup(msg.param_id, -1)
        if i is None:
            self.ep.counters["params_unknown"] += 1
            return
        if self.table.set(i, float(msg.param_value)):
            self.ep.send(self.table.value_msg(i))  # every link learns the new value
        else:
            self.ep.counters["params_rejected"] += 1
            self.ep.send(self.table.value_msg(i), link)


def _for_us(msg: object) -> bool:
    return getattr(msg, "target_system", 0) in (0, 1) and getattr(msg, "target_component", 0) in (0, 1)
