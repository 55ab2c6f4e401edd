"""Data-link-loss failsafe, as PX4's ``NAV_DLL_ACT`` / ``COM_DL_LOSS_T``.

The data link counts as *established* once a HEARTBEAT from another system (a ground station,
MAVSDK, a companion computer) has arrived; it is *lost* when no such HEARTBEAT has arrived for
``COM_DL_LOSS_T`` seconds of simulation time while the vehicle is armed and in the air. On the
loss the action ``NAV_DLL_ACT`` runs once (PX4 values: 0 disabled, 1 hold, 2 return to launch,
3 land), with a STATUSTEXT; a HEARTBEAT after the loss re-arms it ("Data link regained"), and,
as on PX4, the mode is not changed back.

Together with the offboard-loss fallback of :mod:`sitl.autopilot.flight_modes` (no setpoint for
``COM_OF_LOSS_T`` = 1 s: hold), a vehicle whose offboard controller disappears with the link
*holds* first and then, ``COM_DL_LOSS_T`` after the last heartbeat, *lands* (the default here).
A client that never sends a HEARTBEAT (a bare pymavlink script) never establishes the link and
never triggers the failsafe.

Defaults differ from PX4's (NAV_DLL_ACT 0): this simulator lands, because a search vehicle
left without its ground link should come down where it is, not hover until its battery dies.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from sitl.autopilot.flight_modes import FlightController
from sitl.link.endpoint import SYSTEM_ID, Endpoint, Link
from sitl.link.params import Param, ParamTable

DLL_DISABLED, DLL_HOLD, DLL_RTL, DLL_LAND = 0, 1, 2, 3


class DataLinkFailsafe:
    """Watches the HEARTBEATs of other systems and applies ``NAV_DLL_ACT`` when they stop.

    Attributes:
        timeout_s: ``COM_DL_LOSS_T``, simulation seconds without a heartbeat that count as a loss.
        action: ``NAV_DLL_ACT`` (0 disabled, 1 hold, 2 RTL, 3 land).
        last_heartbeat_t: simulation time of the last heartbeat of another system (nan: never).
        lost: the link is lost now; ``losses``: how many times it was lost.
    """

    def __init__(self, ep: Endpoint, fc: FlightController, clock: Callable[[], float], table: ParamTable,
                 timeout_s: float = 10.0, action: int = DLL_LAND) -> None:  # fmt: skip
        self.fc = fc
        self.clock = clock
        self.timeout_s = float(timeout_s)
        self.action = int(action)
        self.last_heartbeat_t = math.nan
        self.lost = False
        self.losses = 0
        ep.rx_hooks.append(self.on_rx)
        table.add(Param("NAV_DLL_ACT", lambda: float(self.action), lambda v: setattr(self, "action", int(v)), 0, 3))
        table.add(Param("COM_DL_LOSS_T", lambda: self.timeout_s, lambda v: setattr(self, "timeout_s", float(v)),
                        0.5, 300))  # fmt: skip

    def on_rx(self, msg: Any, link: Link) -> None:
        if msg.get_type() != "HEARTBEAT" or msg.get_srcSystem() == SYSTEM_ID:
            return
        self.last_heartbeat_t = self.clock()
        if self.lost:
            self.lost = False
            self.fc.say("Data link regained", 5)

    def on_mode_tick(self, _sim: Any = None) -> None:
        """Check for a loss (a ``Simulation.step_hooks`` entry: every slow tick)."""
        if self.lost or self.action == DLL_DISABLED or math.isnan(self.last_heartbeat_t):
            return
        fc = self.fc
        if self.clock() - self.last_heartbeat_t <= self.timeout_s or not fc.armed or fc.on_ground:
            return
        self.lost = True
        self.losses += 1
        what = {DLL_HOLD: "holding", DLL_RTL: "returning to launch", DLL_LAND: "landing"}.get(self.action, "")
        fc.say(f"Data link lost: {what}"[:50], 2)
        if self.action == DLL_HOLD:
            fc.hold()
        elif self.action == DLL_RTL:
            fc.rtl()
        elif self.action == DLL_LAND:
            fc.land()
