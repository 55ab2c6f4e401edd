"""Flight modes of the built-in autopilot: arming, take-off, hold, offboard, waypoint mission,
land and return-to-launch. Plain synchronous Python run at the mode rate (50 Hz); it writes
the setpoint vector read by the numba controller (``sitl.autopilot.controller``).

NED world frame, SI units, yaw in rad (0 = north, positive clockwise seen from above).
Behaviour follows PX4 where the two can be compared: take-off climbs at 1.5 m/s and then
holds, land descends at 0.7 m/s and disarms 2 s after touchdown, offboard needs a setpoint
stream and falls back to hold when it stops, a mission ends in hold unless it lands.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from sitl.autopilot.controller import (
    F_ACC,
    F_ATT,
    F_IDLE,
    F_OFF,
    F_POS,
    F_VEL,
    F_YAW,
    N_SP,
    SP_ACC,
    SP_ATT,
    SP_FLAGS,
    SP_POS,
    SP_THRUST,
    SP_VEL,
    SP_YAW,
    SP_YAWRATE,
)
from sitl.autopilot.mission_exec import MissionExecution
from sitl.autopilot.modes import FlightConfig, ItemKind, LandedState, MissionItem, Mode, StatusEvent
from sitl.autopilot.trajectory import Trajectory, trajectory_setpoint, vec_norm

__all__ = ["F_IDLE", "FlightConfig", "FlightController", "ItemKind", "LandedState", "MissionItem", "Mode",
           "StatusEvent", "Trajectory"]


class FlightController(MissionExecution):
    """Mode logic. Call :meth:`update` at the mode rate with the true state."""

    def __init__(self, config: FlightConfig | None = None, home_yaw: float = 0.0) -> None:
        self.config = config or FlightConfig()
        self.sp = np.zeros(N_SP)
        self.sp[SP_FLAGS] = F_OFF
        self.armed = False
        self.mode = Mode.HOLD
        self.landed_state = LandedState.ON_GROUND
        self.home = np.zeros(3)
        self.events: list[StatusEvent] = []
        self.mission: list[MissionItem] = []
        self.mission_index = 0
        self.mission_reached: list[int] = []  # indices reached since last drain
        self.failsafe = False
        self.crashed = False
        self._traj = Trajectory(np.zeros(3))
        self._yaw = home_yaw
        self._t = 0.0
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._on_ground = True
        self._ground_since = 0.0
        self._hold_until = math.nan
        self._phase = ""
        self._speed = self.config.cruise_speed_m_s
        self._offb_last = -math.inf
        self._offb_sp = np.zeros(N_SP)
        self.prearm_checks: list[Callable[[], str | None]] = []
        self.on_mode_change: list[Callable[[Mode], None]] = []

    # ------------------------------------------------------------------ commands
    @property
    def on_ground(self) -> bool:
        """Ground contact as the land detector sees it (PX4's land detector; the landed state
        stays ON_GROUND/TAKEOFF through spool-up, this is the contact itself)."""
        return self._on_ground

    def say(self, text: str, severity: int = 6) -> None:
        self.events.append(StatusEvent(self._t, severity, text))

    def prearm_failure(self) -> str | None:
        """First failing pre-arm check, or None if the vehicle may arm."""
        if self.crashed:
            return "vehicle crashed"
        if not self._on_ground:
            return "not landed"
        for check in self.prearm_checks:
            reason = check()
            if reason:
                return reason
        return None

    def start_in_air(self, pos_ned: np.ndarray) -> None:
        """Initial condition of an airborne start: armed, in the air, holding at ``pos_ned`` (m, NED)."""
        self._on_ground = False
        self._pos = np.array(pos_ned, dtype=float)
        self.armed = True
        self.landed_state = LandedState.IN_AIR
        self._traj.reset(self._pos)
        self.mode = Mode.HOLD

    def arm(self) -> tuple[bool, str]:
        if self.armed:
            return True, "already armed"
        reason = self.prearm_failure()
        if reason:
            self.say(f"Preflight Fail: {reason}", 3)
            return False, reason
        self.armed = True
        self.home = self._pos.copy()
        self._traj.reset(self._pos)
        self.say("Armed by external command")
        if self.mode in (Mode.LAND, Mode.RTL):
            self._set_mode(Mode.HOLD)
        return True, "armed"

    def disarm(self, force: bool = False) -> tuple[bool, str]:
        if not self.armed:
            return True, "already disarmed"
        if not self._on_ground and not force:
            return False, "not landed (use force to disarm in air)"
        self.armed = False
        self.say("Disarmed by external command" if not force else "Disarmed (forced)")
        self._set_mode(Mode.HOLD)
        return True, "disarmed"

    def takeoff(self, altitude_m: float | None = None) -> tuple[bool, str]:
        alt = self.config.takeoff_altitude_m if altitude_m is None else float(altitude_m)
        if not (math.isfinite(alt) and 0.5 <= alt <= 500.0):
            return False, f"takeoff altitude {alt} outside [0.5, 500] m"
        if not self.armed:
            return False, "not armed"
        self._takeoff_target = np.array([self._pos[0], self._pos[1], self.home[2] - alt])
        self._traj.reset(self._pos)
        self._traj.retarget(self._takeoff_target)
        self._set_mode(Mode.TAKEOFF)
        return True, "taking off"

    def land(self) -> tuple[bool, str]:
        if not self.armed:
            return False, "not armed"
        self._begin_land()
        return True, "landing"

    def rtl(self) -> tuple[bool, str]:
        if not self.armed:
            return False, "not armed"
        self._phase = "climb"
        alt = max(-self._pos[2] + self.home[2], self.config.rtl_altitude_m)
        self._traj.reset(self._pos)
        self._traj.retarget(np.array([self._pos[0], self._pos[1], self.home[2] - alt]))
        self._set_mode(Mode.RTL)
        return True, "returning"

    def hold(self) -> tuple[bool, str]:
        self._enter_hold()
        return True, "holding"

    def reposition(self, pos_ned: np.ndarray, yaw: float = math.nan) -> tuple[bool, str]:
        """Fly to a point and hold there (MAV_CMD_DO_REPOSITION)."""
        if not self.armed or self._on_ground:
            return False, "not flying"
        p = np.where(np.isfinite(pos_ned), pos_ned, self._traj.pos)
        self._traj.retarget(p)
        if math.isfinite(yaw):
            self._yaw = yaw
        self.mode = Mode.HOLD
        self._notify(Mode.HOLD)
        return True, "repositioning"

    def set_speed(self, speed_m_s: float) -> tuple[bool, str]:
        if not (math.isfinite(speed_m_s) and 0.1 <= speed_m_s <= 20.0):
            return False, f"speed {speed_m_s} outside [0.1, 20] m/s"
        self._speed = float(speed_m_s)
        return True, "speed set"

    def offboard_setpoint(
        self,
        t: float,
        pos: np.ndarray | None = None,
        vel: np.ndarray | None = None,
        acc: np.ndarray | None = None,
        yaw: float | None = None,
        yaw_rate: float | None = None,
        attitude: np.ndarray | None = None,
        thrust: float | None = None,
    ) -> None:
        """Store an offboard setpoint (NED, SI). Components left None are not controlled."""
        sp = np.zeros(N_SP)
        flags = 0
        if attitude is not None:
            sp[SP_ATT:SP_ATT + 4] = attitude
            sp[SP_THRUST] = 0.5 if thrust is None else thrust
            flags |= F_ATT
        if pos is not None:
            sp[SP_POS:SP_POS + 3] = pos
            flags |= F_POS
        if vel is not None:
            sp[SP_VEL:SP_VEL + 3] = vel
            flags |= F_VEL
        if acc is not None:
            sp[SP_ACC:SP_ACC + 3] = acc
            flags |= F_ACC
        if yaw is not None:
            sp[SP_YAW] = yaw
            flags |= F_YAW
        if yaw_rate is not None:
            sp[SP_YAWRATE] = yaw_rate
        if flags & (F_POS | F_VEL | F_ACC | F_ATT) == 0:
            return
        sp[SP_FLAGS] = flags
        self._offb_sp = sp
        self._offb_last = t

    def offboard_active(self, t: float) -> bool:
        return t - self._offb_last <= self.config.offboard_timeout_s

    def set_mode(self, mode: Mode) -> tuple[bool, str]:
        """Mode change as requested by a command (DO_SET_MODE)."""
        if mode == Mode.OFFBOARD:
            if not self.offboard_active(self._t):
                return False, "no offboard setpoint stream"
            self._set_mode(Mode.OFFBOARD)
            return True, "offboard"
        if mode == Mode.TAKEOFF:
            return self.takeoff()
        if mode in (Mode.LAND, Mode.RTL):
            if self.armed:
                return self.land() if mode == Mode.LAND else self.rtl()
            self._set_mode(mode)
            return True, "land" if mode == Mode.LAND else "rtl"
        if mode == Mode.MISSION:
            if not self.armed:
                self._set_mode(Mode.MISSION)
                return True, "mission (waiting to arm)"
            return self.start_mission()
        if mode in (Mode.HOLD, Mode.POSITION):
            self._enter_hold(mode)
            return True, mode.value
        return False, f"unsupported mode {mode}"

    # ------------------------------------------------------------------ update
    def update(self, t: float, x: np.ndarray, on_ground: bool, crashed: bool, dt: float) -> np.ndarray:
        """Advance the mode logic to time t with the true state; returns the setpoint vector."""
        self._observe(t, x, on_ground, crashed)
        sp = self.sp
        if not self.armed:
            return self._disarmed_sp(on_ground)
        if self.mode == Mode.OFFBOARD:
            if not self.offboard_active(t):
                self.say("Offboard setpoint stream lost: switching to Hold", 4)
                self._enter_hold()
            else:
                sp[:] = self._offb_sp
                self._traj.reset(self._pos)
                self.landed_state = LandedState.ON_GROUND if on_ground else LandedState.IN_AIR
                if on_ground and int(sp[SP_FLAGS]) & (F_POS | F_VEL) and not self._wants_climb(sp):
                    sp[SP_FLAGS] = F_IDLE
                return sp
        speed = self._step_mode(t)
        if not self.armed:  # landed and disarmed in this step
            sp[:] = 0.0
            sp[SP_FLAGS] = F_OFF
            return sp
        if self.mode in (Mode.LAND, Mode.RTL) and self._phase == "descend":
            return self._descend_sp(on_ground)
        return self._trajectory_sp(dt, speed, on_ground, x)

    def _observe(self, t: float, x: np.ndarray, on_ground: bool, crashed: bool) -> None:
        self._t = t
        self._pos = x[0:3].copy()
        self._vel = x[3:6].copy()
        if on_ground and not self._on_ground:
            self._ground_since = t
        self._on_ground = on_ground
        if crashed and not self.crashed:
            self.crashed = True
            self.failsafe = True
            self.say("Crash detected: motors stopped", 0)
            self.armed = False

    def _disarmed_sp(self, on_ground: bool) -> np.ndarray:
        self.sp[:] = 0.0
        self.sp[SP_FLAGS] = F_OFF
        self.landed_state = LandedState.ON_GROUND if on_ground else LandedState.IN_AIR
        return self.sp

    def _step_mode(self, t: float) -> float:
        """The mode's own logic for this step; returns the speed the trajectory may use (m/s)."""
        speed = self._speed
        if self.mode == Mode.TAKEOFF:
            speed = self.config.takeoff_speed_m_s
            if abs(self._pos[2] - self._takeoff_target[2]) < 0.3:
                self.say("Takeoff complete")
                self._enter_hold()
        elif self.mode == Mode.LAND:
            self._land_step(t)
        elif self.mode == Mode.RTL:
            self._rtl_step(t)
        elif self.mode == Mode.MISSION:
            speed = self._mission_step(t)
        if self.mode == Mode.TAKEOFF:
            speed = self.config.takeoff_speed_m_s
        return speed

    def _descend_sp(self, on_ground: bool) -> np.ndarray:
        sp = self.sp
        sp[:] = 0.0
        sp[SP_POS:SP_POS + 3] = self._traj.pos
        sp[SP_VEL + 2] = self.config.land_speed_m_s
        sp[SP_YAW] = self._yaw
        sp[SP_FLAGS] = F_POS | F_VEL | F_YAW
        # Only the horizontal position is held: zero the vertical position error.
        sp[SP_POS + 2] = self._pos[2]
        self.landed_state = LandedState.LANDING if not on_ground else LandedState.ON_GROUND
        if on_ground:
            # As PX4's position controller ("flying_but_ground_contact"): no thrust and no corrections
            # once the vehicle touches down. Holding position on the ground in a strong wind made it
            # hop (up to 65 touchdowns and 23 s to disarm at 9 m/s).
            sp[SP_FLAGS] = F_IDLE
        return sp

    def _trajectory_sp(self, dt: float, speed: float, on_ground: bool, x: np.ndarray) -> np.ndarray:
        cfg, sp = self.config, self.sp
        yaw = self._yaw
        if not math.isfinite(yaw):  # hold the current heading (the state's attitude quaternion)
            q = x[6:10]
            yaw = math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))
        # The moving setpoint stepped and written into sp (cleared; position, velocity, acceleration, yaw) at once.
        trajectory_setpoint(self._traj.state, sp, dt, speed, cfg.max_accel_m_s2, self._pos, cfg.max_lead_m, yaw)
        flags = F_POS | F_VEL | F_ACC | F_YAW
        taking_off = self.mode == Mode.TAKEOFF or (
            self.mode == Mode.MISSION
            and self.mission_index < len(self.mission)
            and self.mission[self.mission_index].kind == ItemKind.TAKEOFF
        )
        if on_ground and self._traj.pos[2] > self._pos[2] - 0.2 and not taking_off:
            # Armed on the ground with nowhere to climb to: spin at idle.
            flags = F_IDLE
            self.landed_state = LandedState.ON_GROUND
        elif taking_off:
            # As PX4's EXTENDED_SYS_STATE stream: TAKEOFF only once the land detector says not
            # landed; here, once the ground contact has ended.
            self.landed_state = LandedState.ON_GROUND if on_ground else LandedState.TAKEOFF
        else:
            self.landed_state = LandedState.ON_GROUND if on_ground else LandedState.IN_AIR
        sp[SP_FLAGS] = flags
        return sp

    # ------------------------------------------------------------------ internals
    def _wants_climb(self, sp: np.ndarray) -> bool:
        flags = int(sp[SP_FLAGS])
        if flags & F_POS and sp[SP_POS + 2] < self._pos[2] - 0.3:
            return True
        return bool(flags & F_VEL and sp[SP_VEL + 2] < -0.1)

    def _notify(self, mode: Mode) -> None:
        for cb in self.on_mode_change:
            cb(mode)

    def _set_mode(self, mode: Mode) -> None:
        if mode != self.mode:
            self.mode = mode
            self._notify(mode)

    def _enter_hold(self, mode: Mode = Mode.HOLD) -> None:
        # Hold where the vehicle would come to rest: brake from the current velocity.
        stop = self._pos + self._vel * 0.5
        if self._on_ground:
            stop = self._pos.copy()
        self._traj.reset(self._pos)
        self._traj.retarget(stop)
        self._set_mode(mode)

    def _begin_land(self) -> None:
        self._phase = "descend"
        self._traj.reset(self._pos)
        self._land_touch = math.nan
        self._set_mode(Mode.LAND)

    def _land_step(self, t: float) -> None:
        if self._on_ground:
            if not math.isfinite(self._land_touch):
                self._land_touch = t
                self.say("Landing detected")
            elif t - self._land_touch >= self.config.disarm_after_land_s:
                self.armed = False
                self.say("Disarmed by landing")
                self._set_mode(Mode.HOLD)
        else:
            self._land_touch = math.nan

    def _rtl_step(self, t: float) -> None:
        if self._phase == "climb" and vec_norm(self._traj.pos - self._traj.target) < 0.05:
            self._phase = "return"
            self._traj.retarget(np.array([self.home[0], self.home[1], self._traj.target[2]]))
            self.say("RTL: return at altitude")
        elif self._phase == "return" and vec_norm(self._pos[:2] - self.home[:2]) < 1.0:
            self.say("RTL: land at home")
            self._begin_land()
            self.mode = Mode.RTL
        elif self._phase == "descend":
            self._land_step(t)
