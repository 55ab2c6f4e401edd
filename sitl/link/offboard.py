"""Offboard setpoints: SET_POSITION_TARGET_LOCAL_NED, SET_POSITION_TARGET_GLOBAL_INT, SET_ATTITUDE_TARGET.

Each accepted setpoint refreshes the flight controller's offboard stream at the current
simulation time; OFFBOARD can only be entered while the stream is alive and the controller
falls back to hold (with a STATUSTEXT) when it stops for COM_OF_LOSS_T. The type mask selects
what is controlled (POSITION_TARGET_TYPEMASK / ATTITUDE_TARGET_TYPEMASK). Frames: LOCAL_NED,
LOCAL_OFFSET_NED (position relative to the vehicle), BODY_NED / BODY_OFFSET_NED (rotated by
the current yaw), and the global-int frames for the global message.

A setpoint with a NaN or infinite value in a used field, or out of range (|position| > 10 km,
|velocity| > 30 m/s, |acceleration| > 30 m/s^2, |yaw rate| > 10 rad/s, thrust outside [0, 1],
non-unit quaternion) is dropped and counted in ``endpoint.counters["setpoints_rejected"]``.
"""

from __future__ import annotations

import math

import numpy as np

from sitl.link.endpoint import Endpoint, Link, targets_us
from sitl.link.port import AutopilotPort
from sitl.world.sensors import geodetic_to_ned
from vehicle.frames import quat_to_euler
from wire.dialect import mavlink as mav

IGN_PX, IGN_PY, IGN_PZ = 1, 2, 4
IGN_VX, IGN_VY, IGN_VZ = 8, 16, 32
IGN_AX, IGN_AY, IGN_AZ = 64, 128, 256
IGN_YAW, IGN_YAW_RATE = 1024, 2048
ATT_IGN_THROTTLE, ATT_IGN_ATTITUDE = 64, 128

MAX_POS_M, MAX_VEL_M_S, MAX_ACC_M_S2, MAX_YAW_RATE = 1e4, 30.0, 30.0, 10.0


class RejectedError(ValueError):
    pass


def _vec(vals: tuple[float, float, float], mask: int, bits: tuple[int, int, int], fill: np.ndarray,
         lim: float) -> np.ndarray | None:  # fmt: skip
    """The used components of a setpoint vector; ignored ones take ``fill``; None if all ignored."""
    used = [not (mask & b) for b in bits]
    if not any(used):
        return None
    out = fill.astype(float).copy()
    for i, u in enumerate(used):
        if u:
            v = float(vals[i])
            if not math.isfinite(v) or abs(v) > lim:
                raise RejectedError(f"component {i} = {v}")
            out[i] = v
    return out


class OffboardHandler:
    """SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT and SET_ATTITUDE_TARGET into offboard setpoints."""

    def __init__(self, ep: Endpoint, ap: AutopilotPort) -> None:
        self.ep = ep
        self.ap = ap
        ep.handlers["SET_POSITION_TARGET_LOCAL_NED"] = self.on_local
        ep.handlers["SET_POSITION_TARGET_GLOBAL_INT"] = self.on_global
        ep.handlers["SET_ATTITUDE_TARGET"] = self.on_attitude

    def _reject(self) -> None:
        self.ep.counters["setpoints_rejected"] += 1

    def _apply(self, pos: np.ndarray | None, msg: object, frame: int, rel_pos: bool) -> None:
        ap = self.ap
        mask = int(msg.type_mask)
        yaw_now = float(quat_to_euler(ap.attitude())[2])
        body = frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
        c, s = math.cos(yaw_now), math.sin(yaw_now)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) if body else np.eye(3)
        vel = _vec((msg.vx, msg.vy, msg.vz), mask, (IGN_VX, IGN_VY, IGN_VZ), np.zeros(3), MAX_VEL_M_S)
        acc = _vec((msg.afx, msg.afy, msg.afz), mask, (IGN_AX, IGN_AY, IGN_AZ), np.zeros(3), MAX_ACC_M_S2)
        if vel is not None:
            vel = rot @ vel
        if acc is not None:
            acc = rot @ acc
        if pos is not None and rel_pos:
            pos = ap.position() + rot @ pos
        yaw = None
        if not mask & IGN_YAW:
            if not math.isfinite(msg.yaw):
                raise RejectedError("yaw")
            yaw = float(msg.yaw)
        yaw_rate = None
        if not mask & IGN_YAW_RATE:
            if not (math.isfinite(msg.yaw_rate) and abs(msg.yaw_rate) <= MAX_YAW_RATE):
                raise RejectedError("yaw rate")
            yaw_rate = float(msg.yaw_rate)
        if pos is None and vel is None and acc is None:
            raise RejectedError("nothing to control")
        ap.fc.offboard_setpoint(ap.clock(), pos=pos, vel=vel, acc=acc, yaw=yaw, yaw_rate=yaw_rate)
        self.ep.counters["setpoints"] += 1

    def on_local(self, msg: object, link: Link) -> None:
        if not targets_us(msg):
            return
        frame = int(msg.coordinate_frame)
        if frame not in (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_NED,
                         mav.MAV_FRAME_BODY_OFFSET_NED):  # fmt: skip
            self._reject()
            return
        rel = frame in (mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
        try:
            fill = np.zeros(3) if rel else self.ap.position()
            pos = _vec((msg.x, msg.y, msg.z), int(msg.type_mask), (IGN_PX, IGN_PY, IGN_PZ), fill, MAX_POS_M)
            self._apply(pos, msg, frame, rel)
        except RejectedError:
            self._reject()

    def on_global(self, msg: object, link: Link) -> None:
        if not targets_us(msg):
            return
        frame = int(msg.coordinate_frame)
        if frame not in (mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                         mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT):
            self._reject()
            return
        ap = self.ap
        mask = int(msg.type_mask)
        try:
            pos = None
            if (mask & (IGN_PX | IGN_PY | IGN_PZ)) != (IGN_PX | IGN_PY | IGN_PZ):
                lat, lon, alt = msg.lat_int * 1e-7, msg.lon_int * 1e-7, float(msg.alt)
                if not (-90 <= lat <= 90 and -180 <= lon <= 180 and math.isfinite(alt)):
                    raise RejectedError("lat/lon/alt")
                home = ap.home
                ned = geodetic_to_ned(lat, lon, home.alt_m, home)
                if frame in (mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL):
                    ned[2] = home.alt_m - alt
                else:
                    ned[2] = ap.fc.home[2] - alt
                pos = _vec(tuple(ned), mask, (IGN_PX, IGN_PY, IGN_PZ), ap.position(), MAX_POS_M)
            self._apply(pos, msg, mav.MAV_FRAME_LOCAL_NED, False)
        except RejectedError:
            self._reject()

    def on_attitude(self, msg: object, link: Link) -> None:
        if not targets_us(msg):
            return
        mask = int(msg.type_mask)
        q = np.asarray(msg.q, dtype=float)
        thrust = float(msg.thrust)
        n = float(np.linalg.norm(q)) if np.all(np.isfinite(q)) else math.nan
        if mask & ATT_IGN_ATTITUDE or not (0.9 <= n <= 1.1):
            self._reject()  # rate-only control is not supported by this autopilot
            return
        if mask & ATT_IGN_THROTTLE:
            thrust = 0.5
        if not (math.isfinite(thrust) and 0.0 <= thrust <= 1.0):
            self._reject()
            return
        self.ap.fc.offboard_setpoint(self.ap.clock(), attitude=q / n, thrust=thrust)
        self.ep.counters["setpoints"] += 1
