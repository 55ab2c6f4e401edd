"""The wind UKF's outputs: :class:`WindEstimate` and the read-only views of the filter state.

All NED, m/s (wind = air-mass velocity); covariances in (m/s)^2; directions are FROM-directions
in degrees (0 = from north, 90 = from east). The reported wind covariance is the filter's plus
a model-error term (:meth:`EstimatorOutputs.model_error_cov`), so that the +-2 sigma band stays
honest when the force model is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from estimator.config import EstimatorConfig
from estimator.direction import DirectionFilter, speed_direction
from estimator.model_kernels import unseen_bias_wind_cov


@dataclass
class WindEstimate:
    """One output of the estimator (all NED, m/s; angles in degrees FROM, 0 = north, 90 = east)."""

    t: float
    wind_ned: np.ndarray  # air-mass velocity, NED, m/s
    cov_ned: np.ndarray  # 3x3 covariance of wind_ned, (m/s)^2
    speed_h: float  # horizontal wind speed, m/s
    speed_h_sigma: float
    direction_deg: float  # from-direction, deg in [0, 360)
    direction_sigma_deg: float
    direction_filtered_deg: float  # causal Butterworth-filtered from-direction (heading command)
    airspeed_body: np.ndarray = field(default_factory=lambda: np.zeros(3))  # FRD, m/s

    @property
    def sigma_ned(self) -> np.ndarray:
        """1-sigma of each wind component, m/s (the +-2 sigma band is wind_ned +- 2 sigma)."""
        return np.sqrt(np.maximum(np.diag(self.cov_ned), 0.0))


@njit(cache=True, nogil=True)
def wind_moments(
    x: np.ndarray, P: np.ndarray, R: np.ndarray, has_R: bool, rel_h: float, sigma_d: float
) -> tuple[np.ndarray, np.ndarray]:
    """(reported wind covariance NED (m/s)^2, airspeed in body axes FRD m/s) at state x.

    Covariance: the filter's wind block plus the model-error term (rel_h * horizontal airspeed)^2
    on north and east and sigma_d^2 on down (see :meth:`EstimatorOutputs.model_error_cov`).
    Without an attitude (``has_R`` False) the model-error term and the airspeed are zero.
    """
    C = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C[i, j] = P[3 + i, 3 + j]
    v_air = np.zeros(3)
    if has_R:
        vn = R[0, 0] * x[0] + R[0, 1] * x[1] + R[0, 2] * x[2] - x[3]
        ve = R[1, 0] * x[0] + R[1, 1] * x[1] + R[1, 2] * x[2] - x[4]
        sh = rel_h * np.sqrt(vn * vn + ve * ve)
        C[0, 0] += sh * sh
        C[1, 1] += sh * sh
        C[2, 2] += sigma_d * sigma_d
        for i in range(3):
            v_air[i] = x[i] - (R[0, i] * x[3] + R[1, i] * x[4] + R[2, i] * x[5])
    return C, v_air


_NO_R = np.eye(3)
#: The unseen-bias term is recomputed at most this often [s of filter time]: it follows the airspeed,
#: which changes slowly, and costs four force-model calls (as much as an IMU step).
BIAS_COV_EVERY_S = 0.1


class EstimatorOutputs:
    """Outputs of :class:`estimator.ukf.WindEstimator` (a mixin: the filter holds the state)."""

    config: EstimatorConfig
    x: np.ndarray
    P: np.ndarray
    t: float | None
    _R: np.ndarray | None
    _w_rot: np.ndarray | None
    _rates: np.ndarray
    _p: np.ndarray
    _fz_ref: float
    _bias_cov: tuple[float, np.ndarray] | None  # (filter time, unseen_bias_cov) of the last evaluation
    _i_scale: int
    _bias_idx: np.ndarray
    heading_sigma_rad: float
    direction: DirectionFilter
    _dir_filtered: float

    @property
    def wind_ned(self) -> np.ndarray:
        """Wind (air-mass velocity) NED, m/s."""
        return self.x[3:6].copy()

    @property
    def wind_cov(self) -> np.ndarray:
        """Covariance of the wind (NED, (m/s)^2): the filter's plus the model-error term
        (see :meth:`model_error_cov`). This is what the +-2 sigma band and WIND_COV report."""
        return self._moments()[0]

    def _moments(self) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        R = self._R
        C, v_air = wind_moments(
            self.x, self.P, _NO_R if R is None else R, R is not None, cfg.model_error_rel_h, cfg.model_error_d_m_s
        )
        C[0:2, 0:2] += self.unseen_bias_cov()
        if self.heading_sigma_rad > 0.0:
            C[0:2, 0:2] += self.heading_cov()
        return C, v_air

    def heading_cov(self) -> np.ndarray:
        """Horizontal wind covariance (N, E; (m/s)^2) from the heading uncertainty of the attitude.

        A heading error dpsi turns the air-relative velocity the filter infers from the forces, so the
        wind is off by dpsi x J v_air (v_air the horizontal air-relative velocity NED, J the 90 deg turn):
        sigma^2 (J v)(J v)^T, across the air-relative velocity (``estimator.compass``). Zero without an
        attitude or while no heading sigma is set."""
        s = self.heading_sigma_rad
        if self._R is None or s <= 0.0:
            return np.zeros((2, 2))
        v = self._R[0:2, :] @ self.x[0:3] - self.x[3:5]
        jv = np.array([-v[1], v[0]])
        return s * s * np.outer(jv, jv)

    def unseen_bias_cov(self) -> np.ndarray:
        """Horizontal wind covariance (N, E; (m/s)^2) from the accelerometer bias no state carries.

        At a constant heading a horizontal body-axis accelerometer bias is the same force as a
        wind change (``estimator.config.EstimatorConfig.unseen_accel_bias_m_s2``), so the filter
        cannot shrink it and its own covariance leaves it out; the estimate is off by it for the
        whole flight. Added here, mapped through the force model's wind sensitivity
        (:func:`estimator.model_kernels.unseen_bias_wind_cov`): with the paper's vehicle, 0.02
        m/s^2 is ~0.19 m/s of wind at 5 m/s of airspeed and ~0.12 m/s at 10 m/s. Zero without
        an attitude or rotor speeds, or when both horizontal axes have a bias state."""
        cfg = self.config
        sb = cfg.unseen_accel_bias_m_s2
        if sb <= 0.0 or self._R is None or self._w_rot is None or (self._bias_idx[0] >= 0 and self._bias_idx[1] >= 0):
            return np.zeros((2, 2))
        t = -math.inf if self.t is None else self.t
        cached = self._bias_cov
        if cached is not None and 0.0 <= t - cached[0] < BIAS_COV_EVERY_S:
            return cached[1]
        cov = unseen_bias_wind_cov(self.x, self._R, self._rates, self._w_rot, self._p, self._i_scale,
                                   self._fz_ref, sb, cfg.wind_sigma0_m_s**2)  # fmt: skip
        self._bias_cov = (t, cov)
        return cov

    def model_error_cov(self) -> np.ndarray:
        """Wind covariance (NED, (m/s)^2) from force-model error the filter cannot see.

        A coefficient error of Eq. 46 biases the wind estimate by a constant fraction of the
        airspeed; a bias does not average down, so it is not fed to the filter as white noise
        (that would only make the estimate noisier) but added to the reported covariance:
        (model_error_rel_h * horizontal airspeed)^2 on north and east, and
        model_error_d_m_s^2 on down.
        """
        cfg = self.config
        C = np.zeros((3, 3))
        if self._R is None:
            return C
        v_air_ned = self._R @ self.x[0:3] - self.x[3:6]
        sh = cfg.model_error_rel_h * math.hypot(v_air_ned[0], v_air_ned[1])
        C[0, 0] = C[1, 1] = sh * sh
        C[2, 2] = cfg.model_error_d_m_s**2
        return C

    @property
    def force_scale(self) -> tuple[float, float]:
        """Force-scale estimate and its 1-sigma (dimensionless; (1, 0) without the state)."""
        i = self._i_scale
        if i < 0:
            return 1.0, 0.0
        return float(self.x[i]), float(math.sqrt(max(self.P[i, i], 0.0)))

    @property
    def accel_bias(self) -> tuple[np.ndarray, np.ndarray]:
        """Accelerometer-bias estimate and 1-sigma (FRD, m/s^2); zero on axes without a state."""
        b, sig = np.zeros(3), np.zeros(3)
        for axis, j in enumerate(self._bias_idx):
            if j >= 0:
                b[axis] = self.x[j]
                sig[axis] = math.sqrt(max(self.P[j, j], 0.0))
        return b, sig

    @property
    def state(self) -> np.ndarray:
        return self.x.copy()

    @property
    def covariance(self) -> np.ndarray:
        return self.P.copy()

    def estimate(self, advance_direction: bool = True) -> WindEstimate:
        """Current estimate. ``advance_direction`` feeds the Butterworth one sample (call once per step)."""
        W = self.x[3:6].copy()
        C, v_air = self._moments()
        s, s_sig, d, d_sig = speed_direction(W, C)
        if advance_direction:
            self._dir_filtered = self.direction.update(d)
        return WindEstimate(
            t=float(self.t) if self.t is not None else float("nan"),
            wind_ned=W,
            cov_ned=C,
            speed_h=s,
            speed_h_sigma=s_sig,
            direction_deg=d,
            direction_sigma_deg=d_sig,
            direction_filtered_deg=self._dir_filtered,
            airspeed_body=v_air,
        )
