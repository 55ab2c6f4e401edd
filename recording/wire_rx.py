"""What arrives on a MAVLink link, into a :class:`RunRecorder`: the companions' messages, and an autopilot's own.

:class:`WireRecorder` is the one reader of the wire for every SITL recording: the built-in SITL's
(:mod:`recording.sitl_link`, on its link's ``rx_hooks``) and PX4's or ArduPilot's (:mod:`recording.autopilot_rrd`,
on their runner's ``rx_hooks``: what the autopilot passes windseek's peripheral component).

- **WIND_COV from a companion** (windseek's estimator, component 191): the estimate per axis with its
  +-2 sigma band (``var_horiz`` split equally between N and E, ``var_vert`` on D), the estimate arrow at
  the vehicle, horizontal speed and from-direction raw and low-passed ("filtered"); stamped with its own
  ``time_usec`` (the autopilot's clock, which in lockstep is the simulation's).
- **The autopilot's own estimate** (only when an ``autopilot_label`` is given, component 1): PX4 EKF2's
  WIND_COV at its ``time_usec``; ArduPilot EKF3's WIND (from-direction, horizontal speed, ``speed_z``;
  no time stamp and no covariance) at the vehicle's time of arrival, ``now()``. Without a label (the
  built-in SITL, whose autopilot sends no estimate) every WIND_COV is windseek's.
- **The mission**: its STATUSTEXT (``state: NAME``: the strategy's states, :mod:`wire.names`) and its
  declaration (NAMED_VALUE_FLOAT ``SRC_N/E/D`` then ``SRC_CONF``, stamped with ``time_boot_ms``) drive
  the phases, the path's colours and the events; any other sender's STATUSTEXT goes to the events log.
- **The autopilot's HEARTBEAT and STATUSTEXT** (only with a label): its flight mode (PX4's names,
  ArduPilot's through pymavlink's mode tables) and its messages to the events log.

Conventions: SI, NED, wind = air-mass velocity NED; vehicle (= simulation) seconds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from pymavlink import mavutil

from recording.recorder import RunRecorder
from wire import px4_modes
from wire.names import ESTIMATOR_COMPONENT, MISSION_COMPONENT, SRC_CONF, SRC_NAMES, STATE_PREFIX

#: MAV_COMP_ID_AUTOPILOT1: the autopilot's own messages (and wind estimate).
AUTOPILOT_COMPONENT = 1
MAV_AUTOPILOT_INVALID = 8
MAV_AUTOPILOT_PX4 = 12


def _name(msg: Any) -> str:
    return str(getattr(msg, "name", "")).rstrip("\x00")


def mode_name(hb: Any) -> str:
    """The flight mode of an autopilot's HEARTBEAT: PX4's names (``AUTO.LAND``), else pymavlink's (``GUIDED``)."""
    if int(hb.autopilot) == MAV_AUTOPILOT_PX4:
        return px4_modes.name(int(hb.custom_mode))
    return str(mavutil.mode_string_v10(hb))


def wind_of_wind_msg(msg: Any) -> np.ndarray:
    """ArduPilot's WIND (from-direction deg, horizontal speed m/s, ``speed_z``) as air-mass velocity NED
    [m/s]: air from the east (90 deg) moves west. ``speed_z`` is taken as the down component, as
    :class:`sitl.hil.summary.TruthScore` scores it."""
    d = math.radians(float(msg.direction))
    sp = float(msg.speed)
    return np.array([-sp * math.cos(d), -sp * math.sin(d), float(msg.speed_z)])


class WireRecorder:
    """The wire's messages into ``rec`` (see the module docstring).

    Args:
        rec: the recorder.
        now: the vehicle's clock now [s] (for messages without a time stamp of their own).
        position: the vehicle's true position now [m, NED] (where the estimate's arrow starts).
        autopilot_label: what the autopilot's own estimate is ("PX4 EKF2", "ArduCopter EKF3"), or None
            (the built-in SITL: every WIND_COV is windseek's; the autopilot's messages are not logged here).
        filter_cutoff_hz: cutoff of the first-order low-pass of the "filtered" direction and speed [Hz].
    """

    def __init__(self, rec: RunRecorder, now: Callable[[], float], position: Callable[[], np.ndarray],
                 autopilot_label: str | None = None, filter_cutoff_hz: float = 0.05) -> None:  # fmt: skip
        self.rec, self.now, self.position = rec, now, position
        self.autopilot_label = autopilot_label
        self.tau_s = 1.0 / (2.0 * math.pi * filter_cutoff_hz)
        self._filt: np.ndarray | None = None
        self._t_filt = 0.0
        self.estimates = 0
        self.autopilot_estimates = 0
        self.wind_from: tuple[int, int] | None = None
        self._mode: str | None = None

    def on_message(self, msg: Any) -> tuple[float, np.ndarray] | None:
        """Log one message; returns (t [s], wind [m/s NED]) of a windseek estimate, else None."""
        mtype = msg.get_type()
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        own = self.autopilot_label is not None and src[1] == AUTOPILOT_COMPONENT
        if mtype == "WIND_COV":
            t = msg.time_usec * 1e-6
            w = np.array([float(msg.wind_x), float(msg.wind_y), float(msg.wind_z)])
            if not np.all(np.isfinite(w)):
                return None
            if own:
                self.autopilot_estimates += 1
                self.rec.autopilot_wind(t, w)
                return None
            self.estimate(t, w, float(msg.var_horiz), float(msg.var_vert), src)
            return t, w
        if mtype == "WIND" and own:
            self.autopilot_estimates += 1
            self.rec.autopilot_wind(self.now(), wind_of_wind_msg(msg))
        elif mtype == "STATUSTEXT":
            self._statustext(msg, src, own)
        elif mtype == "NAMED_VALUE_FLOAT":
            name = _name(msg)
            if name in SRC_NAMES or name == SRC_CONF:
                # The mission stamps its declaration with its own tick time (vehicle time).
                self.rec.mission_named_value(msg.time_boot_ms * 1e-3, name, float(msg.value))
        elif mtype == "HEARTBEAT" and own and int(msg.autopilot) != MAV_AUTOPILOT_INVALID:
            mode = mode_name(msg)
            if mode != self._mode:
                self._mode = mode
                self.rec.flight_mode(self.now(), mode)
        return None

    def estimate(self, t: float, w: np.ndarray, var_h: float, var_v: float, src: tuple[int, int]) -> None:
        """windseek's estimate ``w`` [m/s NED] at ``t`` [s] with its variances [m^2/s^2] (horizontal = N + E)."""
        rec = self.rec
        self.estimates += 1
        self.wind_from = src
        sh = math.sqrt(max(var_h, 0.0) / 2.0)
        sv = math.sqrt(max(var_v, 0.0))
        rec.wind(t, est_ned=w, sigma_ned=[sh, sh, sv])
        rec.wind_arrows(t, self.position(), None, w)
        if self._filt is None:
            self._filt = w[:2].copy()
        else:
            a = min(1.0, max(0.0, t - self._t_filt) / self.tau_s)
            self._filt += a * (w[:2] - self._filt)
        self._t_filt = t
        wx, wy = float(w[0]), float(w[1])
        fn, fe = float(self._filt[0]), float(self._filt[1])
        # From-directions with math (vehicle.frames.from_direction_deg's numpy costs ~40 us a call).
        rec.wind_speed_dir(t, math.hypot(wx, wy), math.degrees(math.atan2(-wy, -wx)) % 360.0,
                           math.hypot(fn, fe), math.degrees(math.atan2(-fe, -fn)) % 360.0)  # fmt: skip

    def _statustext(self, msg: Any, src: tuple[int, int], own: bool) -> None:
        text = str(msg.text).rstrip("\x00")
        level = "WARN" if msg.severity <= 4 else "INFO"
        if src[1] == AUTOPILOT_COMPONENT:
            if own:  # PX4's or ArduPilot's own words ("Arming motors", "EKF3 IMU0 is using GPS")
                self.rec.autopilot_event(self.now(), text, level)
            return
        who = {MISSION_COMPONENT: "mission", ESTIMATOR_COMPONENT: "estimator"}.get(src[1], f"{src[0]}:{src[1]}")
        if text.startswith(STATE_PREFIX):
            who = "mission"
        self.rec.mission_statustext(self.now(), text, who, level)

    def source_line(self) -> str:
        """Where windseek's estimates came from, in words (the summary's wind source)."""
        if self.wind_from is None:
            return "none received"
        return f"WIND_COV from system {self.wind_from[0]} component {self.wind_from[1]} ({self.estimates} received)"


__all__ = ["AUTOPILOT_COMPONENT", "WireRecorder", "mode_name", "wind_of_wind_msg"]
