"""``windseek estimator`` on PX4: read PX4's magnetometer calibration and take SCALED_IMU as the IMU and compass.

Why (``estimator/px4_mag.py``, ``LiveCore.use_px4_raw``): PX4's HIGHRES_IMU has EKF2's bias estimates taken
out of all three sensors, and an EKF2 whose heading drifted has explained the drift partly as biases: its
magnetometer then agrees with the wrong heading (the compass check sees a third of it) and its accelerometer
too (the forces the filter reads are turned with the heading, so correcting the heading alone makes the wind
worse). SCALED_IMU carries the accelerometer and gyro as calibrated, without EKF2's estimates, and the raw
field, which the estimator calibrates itself with PX4's ``CAL_MAGn_*`` and ``SENS_BOARD_*`` parameters.
Measured on PX4 paper-s1 flights, evaluation seeds 1000-1009 (``benchmarks/compass_replay.py``): 1-s
horizontal RMSE 0.407 m/s, coverage 0.971, against 0.536 / 0.972 on HIGHRES_IMU with the check on its field.

How, after lock-on to an autopilot that says it is PX4: PARAM_REQUEST_READ by name, first the board's four
parameters and every slot's ``CAL_MAGn_ID`` / ``_PRIO``, then the fields of the enabled slots; up to
:data:`BATCH` requests at a time, what is missing asked again every :data:`RETRY_S`, all within
``timeout_s`` of wall time. Then SCALED_IMU is asked for at :data:`SCALED_IMU_HZ` (SET_MESSAGE_INTERVAL; not
when it already streams that fast, and not at all with ``--request-rates never``, when only a stream already
that fast is taken) and the calibration handed to the core, or one line says why the field stays HIGHRES_IMU's
(a parameter not read in time, several compasses, a power compensation). PX4 sends INT32 parameters bytewise in
the float field (``wire.param_codec``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from estimator import px4_mag
from estimator.live import LiveCore
from wire import param_codec

BATCH = 8  # requests in flight at once (PX4 answers from a short queue)
RETRY_S = 1.0  # a name not answered is asked again after this [s]
SCALED_IMU_HZ = 100.0  # the IMU input's rate (as HIGHRES_IMU's is asked for)
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MSG_ID_SCALED_IMU = 26


class Px4MagSetup:
    """The read of PX4's calibration as a small state machine driven by the estimator's loop (module docstring)."""

    def __init__(self, core: LiveCore, say: Callable[[str], None], timeout_s: float = 8.0,
                 rate_hz: float = SCALED_IMU_HZ, may_request: bool = True) -> None:  # fmt: skip
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ValueError(f"SCALED_IMU rate {rate_hz} Hz: must be > 0")
        self.rate_hz = rate_hz
        self.may_request = may_request  # False (--request-rates never): SCALED_IMU only if it streams fast already
        self.core = core
        self.say = say
        self.timeout_s = timeout_s
        self.values: dict[str, float] = {}
        self._wanted: list[str] = []
        self._asked: dict[str, float] = {}
        self._t0: float | None = None
        self.finished = False
        self.result: str | None = None  # the line said at the end

    def start(self, now: float) -> None:
        """Begin with the board's parameters and every slot's id and priority."""
        self._t0 = now
        self._wanted = list(px4_mag.BOARD_PARAMS) + [f"CAL_MAG{i}_{f}" for i in range(px4_mag.SLOTS)
                                                     for f in ("ID", "PRIO")]  # fmt: skip

    def on_message(self, msg: Any) -> None:
        """Take a PARAM_VALUE this setup asked for (others are ignored)."""
        if self._t0 is None or self.finished or msg.get_type() != "PARAM_VALUE":
            return
        name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else str(msg.param_id)
        if name in self._wanted and name not in self.values:
            self.values[name] = float(param_codec.decode(float(msg.param_value), int(msg.param_type)))

    def poll(self, conn: Any, now: float) -> None:
        """Send what is due, move to the slot's fields, or finish (bounded by ``timeout_s``)."""
        if self._t0 is None or self.finished:
            return
        missing = [n for n in self._wanted if n not in self.values]
        if not missing and len(self._wanted) <= len(px4_mag.BOARD_PARAMS) + 2 * px4_mag.SLOTS:
            for slot in px4_mag.enabled_slots(self.values):
                self._wanted += [f"CAL_MAG{slot}_{f}" for f in px4_mag.SLOT_FIELDS if f not in ("ID", "PRIO")]
            missing = [n for n in self._wanted if n not in self.values]
        if not missing:
            self._finish(conn)
            return
        if now - self._t0 > self.timeout_s:
            self._finish(conn)
            return
        target = self.core.target
        if target is None:
            return
        in_flight = sum(1 for n in missing if now - self._asked.get(n, -1e9) < RETRY_S)
        for name in missing:
            if in_flight >= BATCH:
                break
            if now - self._asked.get(name, -1e9) >= RETRY_S:
                conn.mav.param_request_read_send(target[0], target[1], name.encode(), -1)
                self._asked[name] = now
                in_flight += 1

    def _finish(self, conn: Any) -> None:
        self.finished = True
        cal = px4_mag.from_params(self.values)
        if isinstance(cal, str):
            self.result = f"compass: the field stays the IMU message's (PX4's calibration not redone: {cal})"
            self.say(self.result)
            return
        rate = self.core.select.rate_hz("SCALED_IMU")  # already streaming (measured on the autopilot's clock)?
        target = self.core.target
        if rate is not None and rate >= 0.9 * self.rate_hz:
            self.say(f"SCALED_IMU streams at {rate:.0f} Hz already: taken for the IMU and raw field as it is")
        elif not self.may_request:
            self.result = (f"compass: the field stays the IMU message's (SCALED_IMU at {rate or 0:.0f} Hz, under "
                           f"{self.rate_hz:g}, and rates may not be asked for)")  # fmt: skip
            self.say(self.result)
            return
        elif target is not None:
            conn.mav.command_long_send(target[0], target[1], MAV_CMD_SET_MESSAGE_INTERVAL, 0, float(MSG_ID_SCALED_IMU),
                                       1e6 / self.rate_hz, 0, 0, 0, 0, 0)  # fmt: skip
            self.say(f"requested SCALED_IMU (message {MSG_ID_SCALED_IMU}) at {self.rate_hz:g} Hz for the IMU and "
                     "raw field")  # fmt: skip
        self.core.use_px4_raw(cal)
        self.result = "px4-scaled-imu"


__all__ = ["Px4MagSetup"]
