"""The wind filter's numba unscented arithmetic against filterpy's UnscentedKalmanFilter.

``estimator.ukf.WindEstimator`` runs the sigma-point predict and update as numba kernels;
``estimator.reference.FilterpyWindUKF`` is filterpy's UnscentedKalmanFilter with
MerweScaledSigmaPoints on the same force model. On simulated flight data (paper-s1: hover in a
10 m/s wind, 250 Hz IMU, 50 Hz ESC rotor speeds, 10 Hz velocity) both must give the same mean
and covariance, step after step, for the configuration where they are the same filter (no
force-scale state, no transient boost of the wind noise).
"""

from __future__ import annotations

import numpy as np
import pytest

from estimator.config import EstimatorConfig
from estimator.reference import FilterpyWindUKF
from estimator.sigma_kernels import cholesky_lower, merwe_weights, sigma_points
from estimator.ukf import WindEstimator
from sitl.scenario import load_scenario
from sitl.simulation import T_QUAT, T_WIND, Simulation
from vehicle.frames import quat_to_dcm


@pytest.fixture(scope="module")
def flight() -> tuple[np.ndarray, list, list, list]:
    sim = Simulation(load_scenario("paper-s1").with_duration(6.0), seed=11, record_truth=True)
    sim.run(6.0)
    out = sim.drain()
    return sim.truth_array(), out["imu"], out["esc"], out["gnss"]


def test_sigma_points_and_weights_match_filterpy() -> None:
    from filterpy.kalman import MerweScaledSigmaPoints

    rng = np.random.default_rng(5)
    A = rng.normal(size=(7, 7))
    P = A @ A.T + 0.1 * np.eye(7)
    x = rng.normal(size=7)
    for alpha, beta, kappa in ((1.0, 2.0, 0.0), (0.5, 2.0, 1.0)):
        ref = MerweScaledSigmaPoints(7, alpha=alpha, beta=beta, kappa=kappa)
        Wm, Wc, c = merwe_weights(7, alpha, beta, kappa)
        assert np.allclose(Wm, ref.Wm, rtol=1e-14) and np.allclose(Wc, ref.Wc, rtol=1e-14)
        out = np.zeros((15, 7))
        assert sigma_points(x, P, c, np.zeros((7, 7)), out)
        assert np.allclose(out, ref.sigma_points(x, P), rtol=1e-12, atol=1e-12)
    # Not positive definite: reported, not raised.
    assert not cholesky_lower(-P, 1.0, np.zeros((7, 7)))
    assert not cholesky_lower(np.full((7, 7), np.nan), 1.0, np.zeros((7, 7)))


def test_wind_filter_equals_filterpy_ukf_on_flight_data(flight) -> None:
    truth, imu, esc, gnss = flight
    from vehicle.vehicle_file import load_vehicle

    cfg = EstimatorConfig.preset("calibrated", transient_wind_q_gain=1.0)
    est = WindEstimator(load_vehicle(), cfg)
    ref = FilterpyWindUKF(est._p, cfg, est.x, est.P, est._q_density, est._i_scale, est._bias_idx)
    ei = gi = 0
    w_rot = None
    t_prev = None
    worst = 0.0
    for k, (t, acc, gyr) in enumerate(imu[:1200]):
        while ei < len(esc) and esc[ei][0] <= t:
            est.set_rotor_speeds(esc[ei][0], esc[ei][1])
            w_rot = np.asarray(esc[ei][1], dtype=float)
            ei += 1
        q = truth[k, T_QUAT]
        est.set_attitude(t, q)
        R = quat_to_dcm(q / np.linalg.norm(q))
        assert est.imu(t, acc, gyr)
        if t_prev is not None:
            ref.predict(t - t_prev, R, np.asarray(gyr, dtype=float), w_rot)
        ref.update_accel(np.asarray(acc, dtype=float), R, np.asarray(gyr, dtype=float), w_rot)
        t_prev = t
        # A velocity valid now (no delay to compensate): 3 components, and 2 (north, east).
        while gi < len(gnss) and gnss[gi].t <= t + 1e-9:
            v = np.asarray(gnss[gi].vel_ned, dtype=float)
            v = v if gi % 2 else v[:2]
            if abs(gnss[gi].t - t) < 1e-9:
                assert est.gnss_velocity(t, v)
                ref.update_velocity(v, R)
            gi += 1
        scale = np.sqrt(np.diag(ref.ukf.P))
        worst = max(worst, float(np.max(np.abs(est.x - ref.ukf.x) / scale)))
        assert np.allclose(est.P, ref.ukf.P, rtol=1e-7, atol=1e-12), k
    assert worst < 1e-6, worst
    assert est.accepted["gnss"] >= 8  # both kinds of velocity update were compared
    assert not est.rejected, dict(est.rejected)
    # And it converged on the wind (the comparison is not between two stuck filters).
    assert np.linalg.norm(est.wind_ned[:2] - truth[1199, T_WIND][:2]) < 1.5
