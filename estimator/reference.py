"""filterpy's UnscentedKalmanFilter on the wind filter's model: the yardstick, not an estimator.

:class:`~estimator.ukf.WindEstimator` runs the unscented filter as numba kernels
(``estimator.sigma_kernels``). This module sets up the same filter with filterpy (the
library's ``UnscentedKalmanFilter`` and ``MerweScaledSigmaPoints``, its per-sigma-point process
and measurement functions calling the same force-model kernels) so that
``tests/test_estimator_reference.py`` can check the two agree on the same data and
``benchmarks/estimator_speed.py`` can time both. No consumer uses it.

It covers the standard filter: the optimal gain, process noise diag(q) dt. The wind filter
adds a restricted gain for the force-scale state and a transient detector that raises the wind
process noise; compare with a configuration without the scale state and with
``transient_wind_q_gain = 1`` (the ``calibrated`` preset with that override), where the two are
the same filter. Like the wind filter, every update draws its sigma points from the current
(x, P) (filterpy does this after a predict; a second update in the same step would otherwise
reuse stale points). Units and frames: see ``estimator.ukf``.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from estimator.config import EstimatorConfig
from estimator.model_kernels import accel_batch, process_batch


class FilterpyWindUKF:
    """The wind filter's state, noise and models in filterpy.

    Args:
        p: flat vehicle parameter array (``VehicleParams.as_array()``).
        config: the wind filter's tuning; its initial state and noise are used.
        x0, P0, q_density: initial mean, covariance and process-noise density per state (take
            them from a fresh ``WindEstimator``: ``est.x``, ``est.P``, ``est._q_density``).
        i_scale: force-scale state index (-1: none); bias_idx: accelerometer-bias state per
            body axis (-1: none).
    """

    def __init__(
        self,
        p: np.ndarray,
        config: EstimatorConfig,
        x0: np.ndarray,
        P0: np.ndarray,
        q_density: np.ndarray,
        i_scale: int = -1,
        bias_idx: np.ndarray | None = None,
    ) -> None:
        n = x0.shape[0]
        self.p = p
        self.config = config
        self.q = np.asarray(q_density, dtype=float).copy()
        self.i_scale = i_scale
        self.bias_idx = np.full(3, -1, dtype=np.int64) if bias_idx is None else bias_idx
        points = MerweScaledSigmaPoints(n, alpha=config.alpha, beta=config.beta, kappa=config.kappa)
        self.ukf = UnscentedKalmanFilter(dim_x=n, dim_z=3, dt=0.004, hx=self._hx_accel, fx=self._fx, points=points)
        self.ukf.x = np.asarray(x0, dtype=float).copy()
        self.ukf.P = np.asarray(P0, dtype=float).copy()
        self.R_accel = np.diag(np.square(config.accel_noise_m_s2))
        self.R_gnss = np.diag(np.square(config.gnss_vel_noise_m_s))

    def _fx(self, x: np.ndarray, dt: float, R: np.ndarray, rates: np.ndarray, w_rot: np.ndarray,
            decay: float, fz_ref: float) -> np.ndarray:  # fmt: skip
        out = np.empty((1, x.shape[0]))
        process_batch(x[None, :], out, dt, R, rates, w_rot, self.p, decay, self.i_scale, fz_ref)
        return out[0]

    # filterpy passes the measurement function's extra arguments as keywords next to its own R
    # (the noise covariance), hence R_ for the attitude.
    def _hx_accel(
        self, x: np.ndarray, R_: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, fz_ref: float
    ) -> np.ndarray:
        h = accel_batch(x[None, :], R_, rates, w_rot, self.p, self.i_scale, self.bias_idx, fz_ref)
        return np.asarray(h[0])

    @staticmethod
    def _hx_velocity(x: np.ndarray, R_: np.ndarray, nz: int) -> np.ndarray:
        return np.asarray((R_ @ x[0:3])[:nz])

    def predict(self, dt: float, R: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, fz_ref: float = -9.81) -> None:
        """One process step of ``dt`` seconds with the held inputs (attitude DCM, rates, rotor speeds)."""
        tau = self.config.vertical_wind_tau_s
        decay = float(np.exp(-dt / tau)) if tau else 1.0
        self.ukf.Q = np.diag(self.q * dt)
        self.ukf.predict(dt=dt, R=R, rates=rates, w_rot=w_rot, decay=decay, fz_ref=fz_ref)

    def update_accel(self, z: np.ndarray, R: np.ndarray, rates: np.ndarray, w_rot: np.ndarray,
                     fz_ref: float = -9.81) -> None:  # fmt: skip
        """Accelerometer update (specific force FRD, m/s^2)."""
        self._redraw()
        self.ukf.update(z, R=self.R_accel, R_=R, rates=rates, w_rot=w_rot, fz_ref=fz_ref)

    def update_velocity(self, z: np.ndarray, R: np.ndarray) -> None:
        """NED velocity update (m/s; 3 components, or 2 = north, east)."""
        nz = z.shape[0]
        self._redraw()
        self.ukf.update(z, R=self.R_gnss[:nz, :nz], hx=self._hx_velocity, R_=R, nz=nz)

    def _redraw(self) -> None:
        self.ukf.sigmas_f = self.ukf.points_fn.sigma_points(self.ukf.x, self.ukf.P)
