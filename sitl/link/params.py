"""Parameter protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_SET, as PX4 answers them.

The table (:class:`ParamTable`) and the protocol (:class:`ParamProtocol`); which parameters the
SITL has is :mod:`sitl.link.sim_params`. Like PX4, a parameter is ``MAV_PARAM_TYPE_INT32`` or
``MAV_PARAM_TYPE_REAL32`` and an INT32 travels bytewise in the float field
(:mod:`wire.param_codec`). Names (at most 16 characters), type as in PX4's ``*_params.c``:

- ``CTL_<GAIN>`` (REAL32): the controller gains and limits of
  :class:`sitl.autopilot.controller.ControllerGains` (e.g. ``CTL_POS_P_XY``), SI units and rad; live.
- PX4 names for the flight-mode settings of :class:`sitl.autopilot.flight_modes.FlightConfig`, all
  REAL32 as in PX4: ``MIS_TAKEOFF_ALT`` (m), ``MPC_TKO_SPEED``, ``MPC_LAND_SPEED``, ``MPC_XY_CRUISE``
  (m/s), ``RTL_RETURN_ALT`` (m), ``COM_OF_LOSS_T`` (s, offboard loss timeout), ``COM_DISARM_LAND`` (s).
- ``GF_ACTION`` (INT32: 0 none, 1 warning, 2 hold, 3 return, 4 land): what a geofence breach does.
- ``NAV_DLL_ACT`` (INT32), ``COM_DL_LOSS_T`` (INT32, s): the data-link-loss failsafe (:mod:`sitl.link.datalink`).
- ``MAV_SYS_ID`` (INT32, read-only, 1).
- Simulation knobs (REAL32, simulation only, see :mod:`sitl.link.sim_params`): ``SIM_SPEED``,
  ``SIM_WIND_N/E/D``, ``SIM_TURB_SCALE``, ``SIM_*_NOISE``.

PARAM_SET is answered as PX4's ``mavlink_parameters.cpp`` does: an unknown name gets PARAM_ERROR
``DOES_NOT_EXIST``, a type other than INT32/REAL32 ``TYPE_UNSUPPORTED``, the wrong one of the two
``TYPE_MISMATCH`` (no PARAM_VALUE, the value stays), and an accepted set a PARAM_VALUE on every link.
Where this SITL is stricter than PX4 (PX4 does not range-check a PARAM_SET), a read-only, NaN or
out-of-range value is refused with PARAM_ERROR (``READ_ONLY`` / ``VALUE_OUT_OF_RANGE``) followed
by a PARAM_VALUE with the unchanged value, and a locked parameter (``SIM_*`` without
``--allow-sim-params``) with ``PERMISSION_DENIED`` and the unchanged value. Every refusal is counted.
Replies to a read or a refused set go to the peer that asked only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sitl.link.endpoint import Endpoint, Link
from wire import param_codec
from wire.dialect import mavlink

INT32 = param_codec.INT32
REAL32 = param_codec.REAL32


@dataclass
class Param:
    """One parameter: name, how to read and write it (None: read-only), allowed range, PX4 type.

    ``locked``: when it returns a reason (a str), a PARAM_SET over MAVLink is refused with it."""

    name: str
    get: Callable[[], float]
    set: Callable[[float], None] | None
    lo: float
    hi: float
    type: int = REAL32
    locked: Callable[[], str | None] | None = None


class ParamTable:
    """The parameters of one SITL instance, in a fixed order (indices are stable)."""

    def __init__(self, params: list[Param]) -> None:
        self.params: list[Param] = []
        self.by_name: dict[str, int] = {}
        for p in params:
            self.add(p)

    def add(self, p: Param) -> None:
        """Append a parameter (ValueError on a duplicate, a name over 16 characters or another type)."""
        if p.name in self.by_name or len(p.name) > 16:
            raise ValueError(f"parameter {p.name!r}: duplicate or longer than 16 characters")
        if p.type not in (INT32, REAL32):
            raise ValueError(f"parameter {p.name!r}: type {p.type} is neither INT32 nor REAL32 (PX4 has only those)")
        self.by_name[p.name] = len(self.params)
        self.params.append(p)

    def value(self, index: int) -> float | int:
        """The current value of a parameter (an int for INT32)."""
        p = self.params[index]
        v = p.get()
        return int(v) if p.type == INT32 else float(v)

    def value_msg(self, index: int) -> Any:
        """PARAM_VALUE of one parameter, its value encoded as PX4 does."""
        p = self.params[index]
        field = param_codec.encode(self.value(index), p.type)
        return mavlink.MAVLink_param_value_message(p.name.encode(), field, p.type, len(self.params), index)

    def lookup(self, name: str | bytes, index: int) -> int | None:
        if isinstance(name, bytes):
            name = name.decode("ascii", "replace")
        name = name.rstrip("\x00")
        if index >= 0:
            return index if index < len(self.params) else None
        return self.by_name.get(name)

    def check(self, index: int, value: float | int) -> int | None:
        """Why ``value`` cannot be set (a MAV_PARAM_ERROR), or None if it can."""
        p = self.params[index]
        if p.set is None:
            return mavlink.MAV_PARAM_ERROR_READ_ONLY
        v = float(value)
        if not math.isfinite(v) or not (p.lo <= v <= p.hi) or (p.type == INT32 and not v.is_integer()):
            return mavlink.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE
        return None

    def set(self, index: int, value: float | int) -> bool:
        """Set a parameter (the SITL's own API: no lock applies); False (unchanged) if read-only,
        non-finite, out of range or not an integer for an INT32."""
        if self.check(index, value) is not None:
            return False
        p = self.params[index]
        assert p.set is not None
        try:
            p.set(int(value) if p.type == INT32 else float(value))
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

    def _error(self, msg: Any, link: Link, code: int, name: str = "", index: int = -1) -> None:
        self.ep.reply(mavlink.MAVLink_param_error_message(msg.get_srcSystem(), msg.get_srcComponent(),
                                                          name.encode()[:16], index, code), link)  # fmt: skip

    def on_request_list(self, msg: Any, link: Link) -> None:
        if not _for_us(msg):
            return
        self.ep.reply_many([self.table.value_msg(i) for i in range(len(self.table.params))], link)

    def on_request_read(self, msg: Any, link: Link) -> None:
        if not _for_us(msg):
            return
        i = self.table.lookup(msg.param_id, int(msg.param_index))
        if i is None:
            self.ep.counters["params_unknown"] += 1
            index = int(msg.param_index)
            self._error(msg, link, mavlink.MAV_PARAM_ERROR_DOES_NOT_EXIST, "" if index >= 0 else _name(msg), index)
            return
        self.ep.reply(self.table.value_msg(i), link)

    def on_set(self, msg: Any, link: Link) -> None:
        if not _for_us(msg):
            return
        name = _name(msg)
        i = self.table.lookup(name, -1)
        if i is None:
            self.ep.counters["params_unknown"] += 1
            self._error(msg, link, mavlink.MAV_PARAM_ERROR_DOES_NOT_EXIST, name)
            return
        p = self.table.params[i]
        ptype = int(msg.param_type)
        if ptype not in (INT32, REAL32) or ptype != p.type:
            self.ep.counters["params_rejected"] += 1
            self.ep.counters["params_type_mismatch"] += 1
            bad = param_codec.PARAM_ERROR_TYPE_MISMATCH if ptype in (INT32, REAL32) else \
                param_codec.PARAM_ERROR_TYPE_UNSUPPORTED
            self._error(msg, link, bad, name)
            return
        value: float | int = param_codec.wire_int32(msg) if ptype == INT32 else float(msg.param_value)
        lock = p.locked() if p.locked is not None else None
        code = mavlink.MAV_PARAM_ERROR_PERMISSION_DENIED if lock else self.table.check(i, value)
        if code is None and self.table.set(i, value):
            self.ep.send(self.table.value_msg(i))  # every link learns the new value, as PX4 broadcasts
            return
        self.ep.counters["params_rejected"] += 1
        if lock:
            self.ep.counters["params_locked"] += 1
        self._error(msg, link, code if code is not None else mavlink.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, name)
        self.ep.reply(self.table.value_msg(i), link)


def _name(msg: Any) -> str:
    raw = msg.param_id
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return str(raw).rstrip("\x00")


def _for_us(msg: Any) -> bool:
    return getattr(msg, "target_system", 0) in (0, 1) and getattr(msg, "target_component", 0) in (0, 1)
