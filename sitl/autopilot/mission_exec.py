"""Waypoint-mission execution of the built-in autopilot (a part of :class:`FlightController`).

Items are taken in order: take-off, waypoints (with hold times and acceptance radii), speed
changes, land, return to launch. NED, SI; a NaN coordinate of an item means "keep current".
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from sitl.autopilot.modes import FlightConfig, ItemKind, MissionItem, Mode
from sitl.autopilot.trajectory import vec_norm, waypoint_reached

if TYPE_CHECKING:
    from sitl.autopilot.trajectory import Trajectory


class MissionExecution:
    """Mission state and stepping; mixed into :class:`~sitl.autopilot.flight_modes.FlightController`,
    whose mode machinery (``_traj``, ``_set_mode``, ``_begin_land``, ``rtl`` ...) it uses."""

    config: FlightConfig
    mission: list[MissionItem]
    mission_index: int
    mission_reached: list[int]
    armed: bool
    home: np.ndarray
    _traj: Trajectory
    _pos: np.ndarray
    _vel: np.ndarray
    _on_ground: bool
    _hold_until: float
    _phase: str
    _speed: float
    _yaw: float

    if TYPE_CHECKING:  # the mode machinery of FlightController this part calls

        def _set_mode(self, mode: Mode) -> None: ...

        def _begin_land(self) -> None: ...

        def _enter_hold(self, mode: Mode = ...) -> None: ...

        def rtl(self) -> tuple[bool, str]: ...

        def say(self, text: str, severity: int = 6) -> None: ...

    def set_mission(self, items: list[MissionItem]) -> None:
        self.mission = list(items)
        self.mission_index = 0

    def start_mission(self, index: int | None = None) -> tuple[bool, str]:
        if not self.mission:
            return False, "no mission"
        if not self.armed:
            return False, "not armed"
        if index is not None:
            if not 0 <= index < len(self.mission):
                return False, f"mission index {index} outside [0, {len(self.mission) - 1}]"
            self.mission_index = index
        if self.mission_index >= len(self.mission):
            self.mission_index = 0
        self._traj.reset(self._pos)
        self._start_item()
        self._set_mode(Mode.MISSION)
        return True, "mission started"

    def _start_item(self) -> None:
        self._hold_until = math.nan
        while self.mission_index < len(self.mission):
            item = self.mission[self.mission_index]
            if item.kind == ItemKind.CHANGE_SPEED:
                if math.isfinite(item.speed_m_s) and item.speed_m_s > 0:
                    self._speed = item.speed_m_s
                self.mission_reached.append(self.mission_index)
                self.mission_index += 1
                continue
            target = self._item_target(item)
            if item.kind == ItemKind.LAND:
                self._traj.retarget(np.array([target[0], target[1], self._traj.pos[2]]))
                self._phase = "approach"
            elif item.kind == ItemKind.RTL:
                self.mission_reached.append(self.mission_index)
                self.rtl()
                return
            else:
                self._traj.retarget(target)
            if math.isfinite(item.yaw_rad):
                self._yaw = item.yaw_rad
            elif item.kind in (ItemKind.WAYPOINT, ItemKind.LOITER_TIME):
                d = target[:2] - self._pos[:2]
                if np.hypot(*d) > 2.0:
                    self._yaw = math.atan2(d[1], d[0])
            return

    def _item_target(self, item: MissionItem) -> np.ndarray:
        p = item.position_ned.copy()
        ref = self._traj.target
        for i in range(3):
            if not math.isfinite(p[i]):
                p[i] = ref[i]
        if item.kind == ItemKind.TAKEOFF and not math.isfinite(item.position_ned[2]):
            p[2] = self.home[2] - self.config.takeoff_altitude_m
        if item.kind == ItemKind.TAKEOFF:
            p[0], p[1] = self._pos[0], self._pos[1]
        return p

    def _mission_step(self, t: float) -> float:
        if self.mission_index >= len(self.mission):
            return self._speed
        item = self.mission[self.mission_index]
        speed = self.config.takeoff_speed_m_s if item.kind == ItemKind.TAKEOFF else self._speed
        if item.kind == ItemKind.LAND:
            near = vec_norm(self._pos[:2] - self._traj.target[:2])
            if near < max(item.acceptance_radius_m, 0.5):
                self.mission_reached.append(self.mission_index)
                self.mission_index += 1
                self._begin_land()
            return speed
        reached = waypoint_reached(self._traj.state, self._pos, max(item.acceptance_radius_m, 0.3))
        if item.kind == ItemKind.TAKEOFF:
            reached = bool(abs(self._pos[2] - self._traj.target[2]) < 0.3 and abs(self._vel[2]) < 0.5
                           and not self._on_ground)  # fmt: skip
        if reached:
            hold = item.hold_s
            if not math.isfinite(self._hold_until):
                self._hold_until = t + hold
            if t >= self._hold_until:
                self.mission_reached.append(self.mission_index)
                self.mission_index += 1
                if self.mission_index >= len(self.mission):
                    self.say("Mission finished, loitering")
                    self._enter_hold()
                else:
                    self._start_item()
        return speed

