"""The identification manoeuvre as PX4 offboard setpoints: attitude + collective thrust (SET_ATTITUDE_TARGET).

**Why this route.** The paper added its multisine to the motor commands. PX4 (main, 2026-03) takes no motor,
torque or actuator setpoint from MAVLink in offboard mode: ``MavlinkReceiver`` fills
``offboard_control_mode`` only with position / velocity / acceleration (SET_POSITION_TARGET_*,
``src/modules/mavlink/mavlink_receiver.cpp`` 1125-1141 and 1249-1265) or attitude / body rate
(SET_ATTITUDE_TARGET, 1644-1650); the ``thrust_and_torque`` and ``direct_actuator`` flags of
``msg/OffboardControlMode.msg`` (lines 10-11) are set only by uORB / uXRCE-DDS clients. So the multisine
goes in one level up, on the attitude and the collective thrust (SET_ATTITUDE_TARGET with a quaternion and
a thrust, body rates ignored: MAVSDK ``Offboard.set_attitude``), and PX4's own attitude and rate controllers
and its control allocator turn it into motor commands, which are recorded as they are (the equation error
uses the rotor speeds the motors got, whatever put them there). Body-rate setpoints
(``set_attitude_rate``) would reach the moments more directly but leave the attitude loop to the
companion over the link (latency, 50 Hz): attitude setpoints keep PX4 in charge of the attitude.

**The four virtual actuators (Eq. 40) on the setpoint.** The designed multisine (:mod:`identify.design`,
disjoint harmonics per input) is evaluated with unit scale and each input multiplied by its amplitude:

- ``delta_t`` (collective, sum of squared rotor speeds): thrust is proportional to the squared rotor speed,
  so a fraction ``a_t`` of the hover ``delta_t`` is a fraction ``a_t`` of the hover thrust; PX4's collective
  thrust setpoint is normalized (0..1) and reaches the motors through THR_MDL_FAC, so
  ``thrust = thrust_loop + a_t s_t(t) thrust_hover``;
- ``delta_a``, ``delta_e``, ``delta_r`` (roll, pitch, yaw moments): roll, pitch and yaw offsets (rad) on the
  attitude setpoint. PX4's attitude P loop (MC_ROLL_P 6.5 1/s: about 1 Hz closed loop) and its rate loop turn
  an attitude input into a moment ``I theta''``: it grows with f^2 up to about 1 Hz and as f above (the rate
  loop follows what the attitude loop asks), so the 0.2-3 Hz band excites the moments over the whole band.
  PX4's allocator is the pseudo-inverse of its effectiveness matrix (the paper's M_ix), so the four inputs
  keep their own frequencies at the virtual actuators, up to what the feedback correlates.

**The low-frequency reference** (velocity NED and heading, :meth:`identify.design.Manoeuvre.reference_at`)
is flown by a velocity loop in the companion: desired acceleration = the reference's derivative + velocity
and position errors (position = the reference's integral, so the path does not drift) + an integral on the
vertical error (the hover thrust), turned into a thrust vector, a tilt (limited) and a collective thrust.
Each axis of the reference is scaled (and the vertical one's sign chosen: up) so that its path stays inside
the geofence box and the altitude band (:func:`fit_reference`).

Units SI, angles rad; NED world, FRD body; times s from the start of the manoeuvre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from identify.design import Manoeuvre

G = 9.80665


@dataclass(frozen=True)
class LoopGains:
    """The companion's velocity loop: position (1/s^2) and velocity (1/s) gains, the vertical integral
    (1/s^3), its clamp (m/s^2), the tilt limit of the loop (rad, before the excitation) and the thrust
    setpoint's range (normalized)."""

    kp_xy: float = 0.6
    kv_xy: float = 1.6
    kp_z: float = 1.0
    kv_z: float = 2.5
    ki_z: float = 0.4
    i_max_m_s2: float = 2.5
    max_tilt_rad: float = math.radians(20.0)
    thrust_min: float = 0.08
    thrust_max: float = 0.92


@dataclass(frozen=True)
class AttitudeSetpoint:
    """One SET_ATTITUDE_TARGET: roll, pitch, yaw (rad, NED Euler 3-2-1) and normalized collective thrust."""

    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    thrust: float


@dataclass(frozen=True)
class ReferenceFit:
    """Per-axis signed factors on the reference (north, east, down) and what they did, in words."""

    scale: np.ndarray
    note: str


def fit_reference(manoeuvre: Manoeuvre, fence_m: float, altitude_m: float, floor_m: float, ceiling_m: float,
                  margin_m: float = 5.0) -> ReferenceFit:  # fmt: skip
    """Factors that keep the reference's path (its integral, from the start point) inside a box of
    +-(``fence_m`` - ``margin_m``) horizontally and between ``floor_m`` + ``margin_m`` and ``ceiling_m`` -
    ``margin_m`` of altitude, starting at ``altitude_m``; the vertical sign is the one that climbs more
    than it sinks. ValueError when no altitude room is left."""
    t = np.arange(0.0, manoeuvre.total_s + 0.25, 0.25)
    path = np.array([manoeuvre.position_reference(float(x)) for x in t])
    lo, hi = path.min(axis=0), path.max(axis=0)
    scale = np.ones(3)
    notes = []
    room_h = fence_m - margin_m
    if room_h <= 0.0:
        raise ValueError(f"geofence {fence_m:g} m: must exceed the {margin_m:g} m margin")
    for k, name in ((0, "north"), (1, "east")):
        peak = max(abs(lo[k]), abs(hi[k]))
        if peak > room_h:
            scale[k] = room_h / peak
            notes.append(f"{name} excursion {peak:.0f} m scaled by {scale[k]:.2f}")
    up_room, down_room = ceiling_m - margin_m - altitude_m, altitude_m - floor_m - margin_m
    if up_room <= 0.0 or down_room < 0.0:
        raise ValueError(f"altitude {altitude_m:g} m: needs {margin_m:g} m of room to the floor {floor_m:g} m "
                         f"and the ceiling {ceiling_m:g} m")  # fmt: skip
    sign = -1.0 if hi[2] >= -lo[2] else 1.0  # NED: the larger excursion goes up (negative down)
    climb, sink = (hi[2], -lo[2]) if sign < 0 else (-lo[2], hi[2])
    f = min(1.0, up_room / climb if climb > 0 else 1.0, down_room / sink if sink > 0 else 1.0)
    scale[2] = sign * f
    if f < 1.0:
        notes.append(f"vertical excursion +{climb:.0f} / -{sink:.0f} m scaled by {f:.2f}")
    return ReferenceFit(scale=scale, note="; ".join(notes) or "reference path inside the limits as designed")


class ManoeuvreLaw:
    """Setpoints of one manoeuvre (see the module docstring) flown from ``start_ned`` (m) and heading
    ``yaw0_rad``, with the hover collective thrust ``hover_thrust`` (normalized) and the amplitudes of the
    manoeuvre's virtual multisine already in its design: (thrust fraction, roll rad, pitch rad, yaw rad)."""

    def __init__(self, manoeuvre: Manoeuvre, start_ned: np.ndarray, yaw0_rad: float, hover_thrust: float,
                 fit: ReferenceFit, gains: LoopGains | None = None) -> None:  # fmt: skip
        if not 0.05 <= hover_thrust <= 0.9:
            raise ValueError(f"hover thrust {hover_thrust:.3f}: outside 0.05..0.9 (is the vehicle flying?)")
        self.m = manoeuvre
        self.start = np.asarray(start_ned, dtype=float).copy()
        self.yaw0 = float(yaw0_rad)
        self.hover_thrust = float(hover_thrust)
        self.scale = fit.scale
        self.g = gains or LoopGains()
        self._iz = 0.0
        self._t_last: float | None = None

    def reference(self, tau: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(position NED m, velocity NED m/s, heading rad) of the reference at manoeuvre time ``tau`` (s)."""
        vel, dyaw = self.m.reference_at(tau)
        return self.start + self.scale * self.m.position_reference(tau), self.scale * vel, self.yaw0 + dyaw

    def excitation(self, tau: float) -> np.ndarray:
        """The multisine at ``tau``: (thrust fraction of hover, roll, pitch, yaw offsets rad)."""
        return self.m.virtual_at(np.array([tau]))[0]

    def setpoint(self, tau: float, pos: np.ndarray, vel: np.ndarray) -> AttitudeSetpoint:
        """The setpoint at manoeuvre time ``tau`` (s) for the vehicle at ``pos`` (NED m), ``vel`` (NED m/s)."""
        g = self.g
        p_ref, v_ref, yaw_ref = self.reference(tau)
        h = 0.05
        t_lo = max(tau - h, 0.0)
        a_ff = (self.reference(tau + h)[1] - self.reference(t_lo)[1]) / (tau + h - t_lo)
        ep, ev = p_ref - pos, v_ref - vel
        dt = 0.0 if self._t_last is None else min(max(tau - self._t_last, 0.0), 0.1)
        self._t_last = tau
        self._iz = float(np.clip(self._iz + g.ki_z * (ep[2] + 0.5 * ev[2]) * dt, -g.i_max_m_s2, g.i_max_m_s2))
        acc = a_ff + np.array([g.kp_xy * ep[0] + g.kv_xy * ev[0], g.kp_xy * ep[1] + g.kv_xy * ev[1],
                               g.kp_z * ep[2] + g.kv_z * ev[2] + self._iz])  # fmt: skip
        acc[2] = min(acc[2], 0.7 * G)  # never ask for less than 30 % of the weight
        a_h = math.hypot(acc[0], acc[1])
        a_h_max = (G - acc[2]) * math.tan(g.max_tilt_rad)
        if a_h > a_h_max:
            acc[0:2] *= a_h_max / a_h
        e = self.excitation(tau)
        roll, pitch = tilt_for(acc, yaw_ref)
        f = float(np.linalg.norm(acc - np.array([0.0, 0.0, G])))
        thrust = self.hover_thrust * (f / G + e[0])
        return AttitudeSetpoint(roll_rad=roll + e[1], pitch_rad=pitch + e[2], yaw_rad=yaw_ref + e[3],
                                thrust=float(np.clip(thrust, g.thrust_min, g.thrust_max)))  # fmt: skip


def tilt_for(acc_ned: np.ndarray, yaw_rad: float) -> tuple[float, float]:
    """Roll and pitch (rad, Euler 3-2-1 at heading ``yaw_rad``) whose thrust (along -z body) gives the
    acceleration ``acc_ned`` (m/s^2) against gravity."""
    f = np.asarray(acc_ned, dtype=float) - np.array([0.0, 0.0, G])  # thrust per mass, NED
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    fx, fy, fz = c * f[0] + s * f[1], -s * f[0] + c * f[1], f[2]
    n = math.sqrt(fx * fx + fy * fy + fz * fz)
    return math.asin(max(-1.0, min(1.0, fy / n))), math.atan2(-fx, -fz)
