"""The built-in autopilot's vocabulary: modes, landed states, mission items, limits, status lines.

PX4 names in the values and comments; NED world frame, SI units, yaw in rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum, IntEnum

import numpy as np


class Mode(Enum):
    """Autopilot modes (PX4 names in the values)."""

    HOLD = "AUTO.LOITER"
    POSITION = "POSCTL"
    TAKEOFF = "AUTO.TAKEOFF"
    OFFBOARD = "OFFBOARD"
    MISSION = "AUTO.MISSION"
    LAND = "AUTO.LAND"
    RTL = "AUTO.RTL"


class LandedState(IntEnum):
    """MAV_LANDED_STATE values."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class ItemKind(Enum):
    TAKEOFF = "takeoff"
    WAYPOINT = "waypoint"
    LOITER_TIME = "loiter_time"
    LAND = "land"
    RTL = "rtl"
    CHANGE_SPEED = "change_speed"


@dataclass
class MissionItem:
    """One mission item in NED. ``position_ned`` NaN components mean "keep current"."""

    kind: ItemKind
    position_ned: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    acceptance_radius_m: float = 1.0
    hold_s: float = 0.0
    speed_m_s: float = math.nan
    yaw_rad: float = math.nan


@dataclass
class FlightConfig:
    """Mode-level limits and behaviour (PX4 parameter names in comments)."""

    takeoff_altitude_m: float = 10.0  # MIS_TAKEOFF_ALT
    takeoff_speed_m_s: float = 1.5  # MPC_TKO_SPEED
    land_speed_m_s: float = 0.7  # MPC_LAND_SPEED
    cruise_speed_m_s: float = 5.0  # MPC_XY_CRUISE
    max_accel_m_s2: float = 2.0  # trajectory acceleration
    rtl_altitude_m: float = 15.0  # RTL_RETURN_ALT (above home)
    offboard_timeout_s: float = 1.0  # COM_OF_LOSS_T
    disarm_after_land_s: float = 2.0  # COM_DISARM_LAND
    max_lead_m: float = 4.0  # how far the moving setpoint may run ahead of the vehicle


@dataclass
class StatusEvent:
    t: float
    severity: int  # MAV_SEVERITY: 0 emergency .. 6 info
    text: str
