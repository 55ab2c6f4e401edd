"""The compass check's inputs from the autopilot's message stream (the live core's part of ``estimator.compass``).

What reaches :class:`estimator.compass.CompassHeading`: the attitude the autopilot published last, each
magnetometer sample, the first position (the World Magnetic Model's field there) and the heading 1-sigma the
autopilot states (PX4's ODOMETRY). Which message carries the field:

- by default the chosen IMU message's (``mavlink_decode.magnetometer``: ArduPilot's RAW_IMU / SCALED_IMU
  calibrated field, PX4's HIGHRES_IMU field minus EKF2's magnetometer bias);
- with PX4's calibration read (:meth:`CompassFeed.set_px4_calibration`, ``estimator.px4_mag``; the live core
  then takes SCALED_IMU as its IMU input too, ``LiveCore.use_px4_raw``), PX4's SCALED_IMU raw field
  calibrated here, and nothing else: the field as the compass measures it, with no EKF2 bias taken out.
  SCALED_IMU repeats the last field with every IMU sample; a repeat is weighed once.

The stated heading 1-sigma: the compass's alone when it sees the measured field (ArduPilot's, or PX4's
SCALED_IMU calibrated here); the larger of the compass's and the autopilot's when the field has had the
autopilot's own bias estimate taken out (PX4's HIGHRES_IMU), since part of an autopilot heading error then
hides in the field the check compares with (``autopilot_sigma`` off: the compass's alone).

Plain and synchronous; SI units, gauss, NED world, FRD body.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from estimator import mavlink_decode as dec
from estimator.compass import CompassConfig, CompassHeading
from estimator.px4_mag import Px4MagCalibration
from vehicle.frames import quat_to_dcm


class CompassFeed:
    """Feeds :attr:`heading` from messages (module docstring); each method returns a note to print or None."""

    def __init__(self, config: CompassConfig) -> None:
        self.config = config
        self.heading = CompassHeading(config)
        self.autopilot_yaw_sigma: float | None = None  # the heading 1-sigma the autopilot states (rad)
        self.px4: Px4MagCalibration | None = None
        self._R_pub: np.ndarray | None = None  # the attitude the autopilot published last (DCM body -> NED)
        self._last_raw: tuple[float, float, float] | None = None

    def set_px4_calibration(self, cal: Px4MagCalibration) -> str:
        """Take the field from PX4's SCALED_IMU, calibrated by ``cal``, instead of the IMU message's."""
        self.px4 = cal
        self.heading.restart()  # the offset so far was HIGHRES_IMU's field's: not averaged with the raw field's
        return (f"compass: PX4's raw field (SCALED_IMU) calibrated with {cal.describe()}, not HIGHRES_IMU's "
                "(which has EKF2's magnetometer bias taken out)")  # fmt: skip

    def locate(self, msg: Any) -> str | None:
        """The Earth's field from the first position the autopilot reports."""
        pos = dec.position(msg)
        if pos is None or not self.heading.locate(*pos) or not self.config.enabled:
            return None
        d = math.degrees(self.heading.declination_rad or 0.0)
        return (f"compass: the autopilot's heading is checked against its magnetometer (declination {d:.2f} deg at "
                f"{pos[0]:.4f}, {pos[1]:.4f})")  # fmt: skip

    def attitude(self, msg: Any) -> None:
        """Hold the attitude the autopilot published (the magnetometer samples are rotated by it)."""
        self._R_pub = None if (q := dec.attitude(msg)) is None else quat_to_dcm(q)

    def magnetometer(self, mtype: str, msg: Any, t: float, autopilot: int | None) -> str | None:
        """One IMU message's field, if it is the one the check takes (module docstring)."""
        if self.px4 is not None:
            if mtype != "SCALED_IMU" or autopilot != dec.MAV_AUTOPILOT_PX4:
                return None
            raw = (float(msg.xmag), float(msg.ymag), float(msg.zmag))
            if raw == self._last_raw or not any(raw):
                return None  # the same sample again, or no compass
            self._last_raw = raw
            mag: np.ndarray | None = self.px4.correct(np.array(raw) * 1e-3)  # mgauss -> gauss, body FRD
        else:
            mag = dec.magnetometer(msg, autopilot)
        if mag is None or self._R_pub is None:
            return None
        was_ready = self.heading.ready
        self.heading.sample(t, mag, self._R_pub)
        if self.heading.ready and not was_ready:
            return (f"compass: the autopilot's heading is {math.degrees(self.heading.offset_rad):+.1f} deg off its "
                    "magnetometer's; the attitude is corrected by the running offset")  # fmt: skip
        return None

    def heading_sigma(self) -> float:
        """The heading 1-sigma to state [rad] (module docstring)."""
        own = self.heading.sigma_rad
        if self.px4 is not None or not self.config.autopilot_sigma:
            return own
        return max(own, self.autopilot_yaw_sigma or 0.0)

    def summary(self) -> dict[str, object]:
        """The check's figures, the autopilot's stated sigma and the field's source."""
        ap = self.autopilot_yaw_sigma
        return {**self.heading.summary(), "autopilot_yaw_sigma_deg": None if ap is None else round(math.degrees(ap), 2),
                "field": "px4-scaled-imu-calibrated" if self.px4 is not None else "imu-message"}  # fmt: skip


__all__ = ["CompassFeed"]
