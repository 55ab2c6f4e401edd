"""The autopilot's heading checked against the compass: a heading offset estimated from the magnetometer.

Why: the estimator takes the autopilot's attitude to carry forces between body and world axes, so a heading
error of the autopilot turns the estimated wind with it: an error of dpsi rotates the air-relative velocity,
which puts dpsi x |horizontal airspeed| across the wind (0.17 m/s per degree in a 10 m/s wind). PX4's EKF2
with its drag fusion on was seen to publish a heading 10-14 deg off for whole flights in windseek's world
(`benchmarks/README.md`, "heading excursions"), while its magnetometer, which EKF2 also reads, pointed true.

What: the offset ``dpsi`` [rad] is the rotation about the NED down axis that takes the published attitude to
the compass's, ``R = Rz(dpsi) R_pub`` (positive clockwise seen from above, as yaw). Each magnetometer sample
``m_b`` (body FRD, any unit: only its direction is used) rotated by the published attitude, ``m_n = R_pub
m_b``, should point along the Earth's field; its horizontal angle falls short of the field's declination by
the offset: ``dpsi = declination - atan2(m_n_E, m_n_N)``. The declination is the World Magnetic Model's at
the vehicle's position (:mod:`vehicle.geomag`, as PX4 and ArduPilot take it from their own WMM tables).
Samples are averaged as unit vectors (no +-180 deg wrap) with a first-order low-pass of ``tau_s`` [s], so
that a single distorted sample moves little; a sample whose dip (the angle of ``m_n`` below the horizontal)
differs from the model field's inclination by more than ``max_dip_error_deg`` is distorted (a motor current,
a steel roof) and dropped, counted by reason.

Stated uncertainty: the offset is known to ``sigma_deg`` (a calibrated compass away from motor currents: a
degree; the declination model, the calibration's residual and the autopilot's tilt error projected through
the steep field all go into it). The estimator adds its effect on the wind to the covariance it reports
(``WindEstimator.set_heading_sigma``): sigma^2 x (J v)(J v)^T with v the horizontal air-relative velocity and
J the 90 deg turn. Without a compass (no magnetometer in the IMU messages, or all zeros as PX4 sends without
one) or without a position, nothing is corrected and nothing is added: the estimator then relies on the
autopilot's heading, and says so. When the autopilot states its own heading uncertainty (PX4's ODOMETRY
carries EKF2's yaw variance) and it is the larger, that is stated instead (``autopilot_sigma``).

Where the check sees an error and where it cannot: ArduPilot's RAW_IMU / SCALED_IMU carry the calibrated
field as the compass measures it, so an EKF3 heading error shows in full. PX4's HIGHRES_IMU carries the
field *minus EKF2's in-flight magnetometer bias estimate* (PX4 ``HIGHRES_IMU.hpp``): an EKF2 heading error
that EKF2 has partly explained as a magnetometer bias is partly hidden from the check (measured on PX4 paper-s1
flights: about a third of a 3-8 deg error found); EKF2's own stated yaw sigma (2.4-3.3 deg there) is then what
the covariance carries. PX4's SCALED_IMU field is ``sensor_mag`` before PX4's calibration and is not used
(:func:`estimator.mavlink_decode.magnetometer`).

Plain and synchronous; SI units, NED world, FRD body, attitude quaternions [w, x, y, z] body -> NED.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CompassConfig:
    """Settings of :class:`CompassHeading` (module docstring)."""

    enabled: bool = True
    tau_s: float = 5.0  # low-pass time constant of the offset [s]
    sigma_deg: float = 1.0  # stated 1-sigma of the compass heading [deg]
    max_dip_error_deg: float = 10.0  # a sample this far from the field's inclination is distorted [deg]
    min_samples: int = 25  # samples before the offset is used (half a second at PX4's 50 Hz)
    autopilot_sigma: bool = True  # state the autopilot's own heading 1-sigma (ODOMETRY) when it is larger

    def __post_init__(self) -> None:
        if not (self.tau_s > 0.0 and self.sigma_deg >= 0.0 and self.max_dip_error_deg > 0.0 and self.min_samples >= 1):
            raise ValueError(f"compass settings {self}: tau_s and max_dip_error_deg must be > 0, sigma_deg >= 0, "
                             "min_samples >= 1")  # fmt: skip


class CompassHeading:
    """The offset between the autopilot's heading and the compass's (module docstring)."""

    def __init__(self, config: CompassConfig | None = None) -> None:
        self.config = config or CompassConfig()
        self.declination_rad: float | None = None
        self.inclination_rad: float | None = None
        self.counters: Counter[str] = Counter()
        self._c = 0.0  # low-passed cos(dpsi)
        self._s = 0.0  # low-passed sin(dpsi)
        self._n = 0  # accepted samples
        self._t: float | None = None  # time of the last accepted sample [s]

    def set_field(self, field_ned: tuple[float, float, float] | np.ndarray) -> None:
        """The Earth's field at the vehicle (NED, any unit): its declination and inclination."""
        n, e, d = (float(v) for v in field_ned)
        h = math.hypot(n, e)
        if not (h > 0.0 and math.isfinite(d)):
            raise ValueError(f"Earth field {field_ned}: needs a finite, non-zero horizontal component")
        self.declination_rad = math.atan2(e, n)
        self.inclination_rad = math.atan2(d, h)

    def restart(self) -> None:
        """Forget the averaged offset (the field now comes from another source); the Earth's field is kept."""
        self._c = self._s = 0.0
        self._n = 0
        self._t = None

    def locate(self, lat_deg: float, lon_deg: float, alt_m: float = 0.0) -> bool:
        """Take the field of the World Magnetic Model at a geodetic position (once; later calls do nothing).
        False for a position that is not one (NaN, out of range, 0/0 as an autopilot sends without a fix)."""
        if self.declination_rad is not None:
            return True
        if not (abs(lat_deg) <= 90.0 and abs(lon_deg) <= 180.0) or (lat_deg == 0.0 and lon_deg == 0.0):
            self.counters["bad_position"] += 1
            return False
        from vehicle.geomag import earth_field_ned_gauss

        self.set_field(earth_field_ned_gauss(round(lat_deg, 3), round(lon_deg, 3), round(alt_m, -2)))
        return True

    def sample(self, t: float, mag_body: np.ndarray, R_published: np.ndarray) -> None:  # noqa: N803 - a DCM
        """One magnetometer sample (FRD, any unit) with the attitude the autopilot published for it (DCM body ->
        NED: the caller converts each published attitude once, not each sample)."""
        cfg = self.config
        if not cfg.enabled or self.declination_rad is None or self.inclination_rad is None:
            return
        m = np.asarray(mag_body, dtype=float)
        norm = float(np.linalg.norm(m))
        if not (math.isfinite(norm) and norm > 0.0 and np.all(np.isfinite(R_published))):
            self.counters["no_field" if norm == 0.0 else "bad_value"] += 1
            return
        mn = R_published @ m
        dip = math.atan2(mn[2], math.hypot(mn[0], mn[1]))
        if abs(dip - self.inclination_rad) > math.radians(cfg.max_dip_error_deg):
            self.counters["distorted"] += 1
            return
        dpsi = self.declination_rad - math.atan2(mn[1], mn[0])
        c, s = math.cos(dpsi), math.sin(dpsi)
        if self._n == 0 or self._t is None:
            self._c, self._s = c, s
        else:
            a = 1.0 - math.exp(-max(t - self._t, 0.0) / cfg.tau_s)
            a = max(a, 1.0 / (self._n + 1))  # a plain mean over the first samples: no memory of nothing
            self._c += a * (c - self._c)
            self._s += a * (s - self._s)
        self._n += 1
        self._t = t
        self.counters["accepted"] += 1

    @property
    def ready(self) -> bool:
        """True once the offset rests on enough samples to be used."""
        return self.config.enabled and self._n >= self.config.min_samples

    @property
    def offset_rad(self) -> float:
        """The heading offset dpsi [rad] in (-pi, pi]; 0 until :attr:`ready`."""
        return math.atan2(self._s, self._c) if self.ready else 0.0

    @property
    def sigma_rad(self) -> float:
        """Stated 1-sigma of the corrected heading [rad]; 0 until :attr:`ready` (nothing is stated then)."""
        return math.radians(self.config.sigma_deg) if self.ready else 0.0

    def summary(self) -> dict[str, object]:
        """Figures for a report: the offset and stated sigma (deg, None until ready), the declination used."""
        d = self.declination_rad
        return {"offset_deg": round(math.degrees(self.offset_rad), 2) if self.ready else None,
                "sigma_deg": round(math.degrees(self.sigma_rad), 2) if self.ready else None,
                "declination_deg": None if d is None else round(math.degrees(d), 2),
                "samples": dict(self.counters)}  # fmt: skip

    def correct(self, q_published: np.ndarray) -> np.ndarray:
        """The published attitude turned by the offset about NED down: Rz(dpsi) R_pub as a quaternion."""
        q = np.asarray(q_published, dtype=float)
        if not self.ready:
            return q
        h = 0.5 * self.offset_rad
        cz, sz = math.cos(h), math.sin(h)
        w, x, y, z = q
        # [cz, 0, 0, sz] (x) q: a rotation about the world's z applied after the body -> NED rotation.
        return np.array([cz * w - sz * z, cz * x - sz * y, cz * y + sz * x, cz * z + sz * w])
