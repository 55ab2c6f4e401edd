"""The wind UKF's outputs: :class:`WindEstimate` and the read-only views of the filter state.

All NED, m/s (wind = air-mass velocity); covariances in (m/s)^2; directions are FROM-directions
in degrees (0 = from north, 90 = from east). The reported wind covariance is the filter's plus
a model-error term (:meth:`EstimatorOutputs.model_error_cov`), so that the +-2 sigma band stays
honest when the force model is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from estimator.config import EstimatorConfig
from estimator.direction import DirectionFilter, speed_direction

if TYPE_CHECKING:
    from filterpy.kalman import UnscentedKalmanFilter


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


class EstimatorOutputs:
    """Outputs of :class:`estimator.ukf.WindEstimator` (a mixin: the filter holds the state)."""

    config: EstimatorConfig
    ukf: UnscentedKalmanFilter
    t: float | None
    _R: np.ndarray | None
    _i_scale: int
    _bias_idx: np.ndarray
    direction: DirectionFilter
    _dir_filtered: float

    @property
    def wind_ned(self) -> np.ndarray:
        """Wind (air-mass velocity) NED, m/s."""
        return self.ukf.x[3:6].copy()

    @property
    def wind_cov(self) -> np.ndarray:
        """Covariance of the wind (NED, (m/s)^2): the filter's plus the model-error term
        (see :meth:`model_error_cov`). This is what the +-2 sigma band and WIND_COV report."""
        return self.ukf.P[3:6, 3:6] + self.model_error_cov()

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
        v_air_ned = self._R @ self.ukf.x[0:3] - self.ukf.x[3:6]
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
        return float(self.ukf.x[i]), float(math.sqrt(max(self.ukf.P[i, i], 0.0)))

    @property
    def accel_bias(self) -> tuple[np.ndarray, np.ndarray]:
        """Accelerometer-bias estimate and 1-sigma (FRD, m/s^2); zero on axes without a state."""
        b, sig = np.zeros(3), np.zeros(3)
        for axis, j in enumerate(self._bias_idx):
            if j >= 0:
                b[axis] = self.ukf.x[j]
                sig[axis] = math.sqrt(max(self.ukf.P[j, j], 0.0))
        return b, sig

    @property
    def state(self) -> np.ndarray:
        return self.ukf.x.copy()

    @property
    def covariance(self) -> np.ndarray:
        return self.ukf.P.copy()

    def estimate(self, advance_direction: bool = True) -> WindEstimate:
        """Current estimate. ``advance_direction`` feeds the Butterworth one sample (call once per step)."""
        W = self.ukf.x[3:6].copy()
        C = self.wind_cov
        s, s_sig, d, d_sig = speed_direction(W, C)
        if advance_direction:
            self._dir_filtered = self.direction.update(d)
        v_air = np.zeros(3)
        if self._R is not None:
            v_air = self.ukf.x[0:3] - self._R.T @ W
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
