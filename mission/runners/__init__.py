"""Runners drive a strategy object: in-process lockstep (``inprocess``) and MAVSDK (``mavsdk_runner``).

A runner holds no strategy logic: it builds the :class:`~mission.strategies.base.Observation`
from what the vehicle has, calls ``strategy.update`` at the strategy rate and sends the
setpoint to the autopilot.
"""
