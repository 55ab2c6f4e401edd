"""Source-seeking strategies (issues 6, 19): anemotaxis, surge-cast, zig-zag, infotaxis.

Each is a plain, synchronous, deterministic state machine (observation in, setpoint out; see
``mission.strategies.base``); parameters in ``mission.strategies.params``.
"""

from __future__ import annotations

from mission.strategies.anemotaxis import Anemotaxis
from mission.strategies.base import Observation, Setpoint, Strategy, WindInfo
from mission.strategies.infotaxis import Infotaxis
from mission.strategies.params import CommonParams, ParamError, load_params, params_from_table
from mission.strategies.surge_cast import SurgeCast
from mission.strategies.zigzag import Zigzag

STRATEGIES: dict[str, type] = {
    "anemotaxis": Anemotaxis, "surge-cast": SurgeCast, "zigzag": Zigzag, "infotaxis": Infotaxis,
}


def make_strategy(name: str) -> Strategy:
    """A new strategy object by name (``anemotaxis``, ``surge-cast``, ``zigzag``, ``infotaxis``)."""
    if name not in STRATEGIES:
        raise ParamError(f"unknown strategy {name!r}: choose one of {', '.join(STRATEGIES)}")
    return STRATEGIES[name]()


__all__ = [
    "STRATEGIES", "Anemotaxis", "CommonParams", "Infotaxis", "Observation", "ParamError", "Setpoint", "Strategy",
    "SurgeCast", "WindInfo", "Zigzag", "load_params", "make_strategy", "params_from_table",
]
