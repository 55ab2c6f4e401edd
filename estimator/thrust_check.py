"""Is the vehicle flown the vehicle of the force model? A thrust-consistency check in steady flight.

The wind estimator explains every difference between the measured specific force and the paper's
rotor force model as wind. On another vehicle (PX4 SIH, another airframe, a heavier payload) the
difference is the model error, and the filter turns it into a wind that does not exist: on PX4 SIH
it published [3.7, -8.4, -19.9] m/s. The check needs no wind estimate:

- In the air (the autopilot's landed state is IN_AIR), the rotors' vertical force is the vehicle's
  mass times the measured specific force along body z: ``Z = m f_z`` (``f_z`` about -g in hover),
  however the vehicle accelerates. The model's Z at zero airspeed is ``-(a sum(w^2) + b sum(w))``
  (Eq. 46's zero-airspeed terms, :func:`vehicle.rotor_model.static_thrust_curve`), linear in the
  rotor speed sums, so samples are averaged cheaply.
- The model's Z depends on the airspeed too, which is unknown (the wind is what we estimate). Over
  the airspeeds the model was identified for, with a 25 % margin (horizontal up to 1.25 times the
  identified domain's largest 5th/95th percentile of u and v, :func:`model_domain`; body-z within
  :func:`vertical_domain`), the vehicle at hover shows ``ratio = Z0 / (m f_z)`` between
  :attr:`ThrustCheck.band` (0.52-1.51 for ``nasa_quad``); ``margin`` (10 %) widens that band for
  sensor bias, rotor-speed error (actuator outputs through the motor model) and turbulence.
- What it cannot tell: a rotor's thrust grows with airspeed (translational lift, +36 % at 10 m/s for
  the blade-element nasa_quad) and in descent through the air, so in a strong wind a heavier vehicle
  reads like a lighter wind. In 10 m/s of wind a vehicle 40 % heavier or lighter than its model is
  not distinguishable by thrust; in 3 m/s it is; gross mismatches always are (another airframe: PX4
  SIH's 1 kg quadrotor against the 2.8 kg model).
- Only steady samples count (body rates under ``max_rate_rad_s``, specific force within
  ``accel_tol_m_s2`` of g: the rotor speeds from actuator outputs lag in manoeuvres), averaged over
  ``window_s`` of autopilot time in the air; ``confirm`` windows in a row outside the band are a
  mismatch (said once, latched: the vehicle does not change in flight).
- How different a vehicle must be: in 10 m/s of turbulent wind (paper-s1) the paper's vehicle shows
  1.07-1.11; a vehicle 40 % heavier 1.57 and one 40 % lighter 0.76 are named after two windows
  (4 s of steady flight), one 30 % lighter (0.85-0.88) only sometimes: the wind's effect on the
  rotors and a mass error look alike, and the band must allow for the wind.

A ratio above the band means the rotors spin faster than the model needs for this specific force
(a heavier vehicle, weaker rotors); below it, slower (a lighter vehicle, stronger rotors, or rotor
speeds that are not what the model assumes, such as actuator outputs mapped on another motor curve).

Units SI: rad/s, m/s^2, N; FRD body; times in s of the autopilot's clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vehicle.params import VehicleParams
from vehicle.rotor_model import hover_rotor_speed, static_thrust_curve, wrench

MAV_LANDED_STATE_IN_AIR = 2


@dataclass(frozen=True)
class ThrustCheckConfig:
    """Settings of :class:`ThrustCheck` (see the module docstring)."""

    window_s: float = 2.0
    confirm: int = 2
    min_samples: int = 50
    max_rate_rad_s: float = 0.5
    accel_tol_m_s2: float = 2.0
    margin: float = 0.10
    steady_vertical_m_s: float = 1.0


def model_domain(vehicle: VehicleParams) -> float:
    """The horizontal airspeed (m/s) the model was identified for: the largest magnitude among the 5th and
    95th percentiles of u and v in its ``[model.info]`` domain; else its saturation (``domain_airspeed``)
    or, without one, 4 m/s (the paper's Table 3)."""
    dom = vehicle.model_info.get("domain_p5_p95", {})
    if "u" in dom and "v" in dom:
        return float(max(abs(x) for k in ("u", "v") for x in dom[k]))
    return float(min(vehicle.domain_airspeed_m_s, 4.0) if vehicle.domain_airspeed_m_s < 1e8 else 4.0)


def vertical_domain(vehicle: VehicleParams, steady_vertical_m_s: float = 1.0) -> tuple[float, float]:
    """The body-z airspeeds (m/s) the check allows: +-1.25 times the largest of the identified domain's 5th and
    95th percentiles of w (a descent or climb through the air the identification flew), at least
    +-``steady_vertical_m_s``."""
    w = vehicle.model_info.get("domain_p5_p95", {}).get("w")
    m = 1.25 * max(abs(float(w[0])), abs(float(w[1]))) if w else 0.0
    m = max(m, steady_vertical_m_s)
    return -m, m


def model_band(vehicle: VehicleParams, steady_vertical_m_s: float = 1.0) -> tuple[float, float]:
    """The range of ``Z0 / Z(airspeed)`` at the hover rotor speed over the model's identified envelope."""
    om = np.full(vehicle.n_rotors, hover_rotor_speed(vehicle))
    z0 = wrench(vehicle, np.zeros(3), np.zeros(3), om)[2]
    ratios = []
    w_lo, w_hi = vertical_domain(vehicle, steady_vertical_m_s)
    for vh in np.linspace(0.0, 1.25 * model_domain(vehicle), 7):
        for ang in np.linspace(0.0, math.pi / 2, 4):
            for vz in np.linspace(w_lo, w_hi, 7):
                v_air = np.array([vh * math.cos(ang), vh * math.sin(ang), vz])
                ratios.append(z0 / wrench(vehicle, v_air, np.zeros(3), om)[2])
    return float(min(ratios)), float(max(ratios))


class ThrustCheck:
    """Feed it every IMU sample with the rotor speeds then in force (:meth:`sample`); ``mismatch`` is the
    one-line verdict once confirmed (None while the vehicle is consistent or not yet judged)."""

    def __init__(self, vehicle: VehicleParams, config: ThrustCheckConfig | None = None) -> None:
        self.config = cfg = config or ThrustCheckConfig()
        self._a, self._b = static_thrust_curve(vehicle)  # one rotor: N per (rad/s)^2, N per rad/s
        self.mass = float(vehicle.mass_kg)
        self.g = float(vehicle.gravity_m_s2)
        self.vehicle_name = vehicle.name
        lo, hi = model_band(vehicle, cfg.steady_vertical_m_s)
        self.band = (lo / (1.0 + cfg.margin), hi * (1.0 + cfg.margin))
        self.ratio: float | None = None  # the last window's ratio
        self.windows = 0
        self.outside = 0
        self.skipped = 0  # airborne samples outside the steady bounds
        self.mismatch: str | None = None
        self._clear(math.nan)

    def _clear(self, t: float) -> None:
        self._t0, self._n, self._s2, self._s1, self._fz = t, 0, 0.0, 0.0, 0.0

    def sample(self, t: float, acc: np.ndarray, gyr: np.ndarray, speeds: np.ndarray | None, airborne: bool) -> bool:
        """One IMU sample (specific force FRD m/s^2, rates FRD rad/s) and the rotor speeds (rad/s) then in
        force (None: not known). True when this sample confirmed a mismatch (:attr:`mismatch` is set)."""
        if self.mismatch is not None:
            return False
        cfg = self.config
        if not airborne or speeds is None:
            self._clear(math.nan)  # a window holds flight only
            return False
        fz = float(acc[2])
        steady = (
            fz < 0.0
            and abs(math.sqrt(float(acc[0]) ** 2 + float(acc[1]) ** 2 + fz * fz) - self.g) < cfg.accel_tol_m_s2
            and max(abs(float(gyr[0])), abs(float(gyr[1])), abs(float(gyr[2]))) < cfg.max_rate_rad_s
        )
        if not steady:  # skipped, not a reset: a noisy IMU (PX4 SIH's) has single samples outside any bound
            self.skipped += 1
            return False
        if not math.isfinite(self._t0):
            self._t0 = t
        w = [float(x) for x in speeds]
        self._s2 += sum(x * x for x in w)
        self._s1 += sum(w)
        self._fz += fz
        self._n += 1
        if t - self._t0 < cfg.window_s or self._n < cfg.min_samples:
            return False
        ratio = (self._a * self._s2 + self._b * self._s1) / (self.mass * -self._fz)
        self._clear(math.nan)
        self.ratio = ratio
        self.windows += 1
        lo, hi = self.band
        self.outside = self.outside + 1 if not lo <= ratio <= hi else 0
        if self.outside < cfg.confirm:
            return False
        more = "faster" if ratio > hi else "slower"
        self.mismatch = (f"thrust mismatch: in steady flight the rotors spin {more} than {self.vehicle_name} "
                         f"({self.mass:g} kg) needs: its model's thrust at these rotor speeds is "
                         f"{ratio:.2f} x the measured mass x acceleration (expected {lo:.2f}-{hi:.2f} for any "
                         "airspeed the model covers); this is not the model's vehicle, so the filter would report "
                         "the model error as wind: the wind estimate is withheld")  # fmt: skip
        return True

