"""The compiled run of IMU steps (:meth:`WindEstimator.imu_batch`, :mod:`estimator.imu_batch`) against the
per-sample calls it stands for (``set_rotor_speeds`` for each rotor sample up to a step's time, then
``set_attitude`` and ``imu``): the per-sample methods are the reference, as filterpy is for the UKF step
(``tests/test_estimator_reference.py``). The in-process missions feed the filter through the batch, the
live and MAVLink paths through the per-sample methods, so any drift between the two would split them.

The stream is a hover with hostile samples mixed in (NaN and repeated times, out-of-order rotor samples,
non-finite or out-of-range values, a bad quaternion, a gap in the IMU stream, an IMU rate change) and
GNSS fixes between the runs, as the in-process feed delivers them. Everything the filter keeps must be the
same bit for bit: state, covariance, counts, clocks, the IMU-rate estimate, the velocity history.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.ukf import WindEstimator
from vehicle.vehicle_file import load_vehicle

G = 9.80665
W_HOVER = 394.0  # rad/s, nasa-quad's calm hover


def _stream(seed: int) -> dict[str, np.ndarray]:
    """IMU steps (250 Hz, then 125 Hz after 3 s, a 0.4 s gap at 2 s), rotor samples (50 Hz) and GNSS fixes
    (10 Hz) of a hover in a 5 m/s wind, with bad samples put in on purpose."""
    rng = np.random.default_rng(seed)
    ts = np.concatenate([np.arange(0.004, 2.0, 0.004), np.arange(2.4, 3.0, 0.004), np.arange(3.0, 5.0, 0.008)])
    m = ts.size
    tilt = 0.03 + 0.002 * rng.standard_normal(m)  # rad, nose down into the wind
    qs = np.stack([np.cos(tilt / 2), np.zeros(m), np.sin(tilt / 2), np.zeros(m)], axis=1)
    acc = np.stack([-G * np.sin(tilt) + 0.05 * rng.standard_normal(m), 0.05 * rng.standard_normal(m),
                    -G * np.cos(tilt) + 0.05 * rng.standard_normal(m)], axis=1)  # fmt: skip
    gyr = 0.01 * rng.standard_normal((m, 3))
    esc_t = np.arange(0.0, 5.0, 0.02) + 0.001
    esc_w = W_HOVER + 3.0 * rng.standard_normal((esc_t.size, 4))
    # Hostile samples: each kind of rejection, in the IMU, attitude and rotor streams.
    ts[50] = ts[49]  # a repeated IMU / attitude time
    ts[120] = math.nan  # no time at all
    acc[200, 1] = math.inf
    gyr[260, 2] = 1e3  # beyond the gyro's range
    qs[300] = (0.5, 0.5, 0.5, 0.1)  # not a unit quaternion
    esc_t[40] = esc_t[39]  # a repeated rotor time
    esc_t[80], esc_t[81] = esc_t[81], esc_t[80]  # out of order
    esc_w[120, 2] = -5.0  # a negative rotor speed
    esc_w[160, 0] = math.nan
    gnss_t = np.arange(0.1, 5.0, 0.1)
    return {"ts": ts, "qs": qs, "acc": acc, "gyr": gyr, "esc_t": esc_t, "esc_w": esc_w, "gnss_t": gnss_t}


def _gnss_due(s: dict[str, np.ndarray], t_now: float, k: int, est: WindEstimator) -> int:
    """Deliver the GNSS fixes valid by ``t_now`` (a still vehicle: zero ground velocity)."""
    while k < s["gnss_t"].size and s["gnss_t"][k] <= t_now:
        est.gnss_velocity(float(s["gnss_t"][k]), np.zeros(3))
        k += 1
    return k


def _per_sample(s: dict[str, np.ndarray]) -> WindEstimator:
    est = WindEstimator(load_vehicle())
    ei = k = 0
    for j, t in enumerate(s["ts"]):
        while ei < s["esc_t"].size and s["esc_t"][ei] <= t + 1e-9:
            est.set_rotor_speeds(float(s["esc_t"][ei]), s["esc_w"][ei])
            ei += 1
        est.set_attitude(float(t), s["qs"][j])
        est.imu(float(t), s["acc"][j], s["gyr"][j])
        if math.isfinite(t) and (j + 1 == s["ts"].size or j % 37 == 36):  # a fix between runs of steps
            k = _gnss_due(s, float(t), k, est)
    return est


def _batched(s: dict[str, np.ndarray]) -> WindEstimator:
    est = WindEstimator(load_vehicle())
    ei = k = j0 = 0
    m = s["ts"].size
    while j0 < m:
        j1 = j0
        while j1 < m - 1 and not (math.isfinite(s["ts"][j1]) and j1 % 37 == 36):
            j1 += 1
        sl = slice(j0, j1 + 1)
        ei = est.imu_batch(s["ts"][sl], s["qs"][sl], s["acc"][sl], s["gyr"][sl], s["esc_t"], s["esc_w"], ei)
        if math.isfinite(s["ts"][j1]):
            k = _gnss_due(s, float(s["ts"][j1]), k, est)
        j0 = j1 + 1
    return est


def _kept(est: WindEstimator) -> dict[str, object]:
    """Everything the filter keeps between calls, as comparable values."""
    hist = [(t, (R @ v).tolist()) for t, R, v in est._hist]
    rate = est.imu_rate
    return {
        "x": est.x.tolist(), "P": est.P.tolist(), "t": est.t, "t_first": est._t_first,
        "accepted": dict(est.accepted), "rejected": dict(est.rejected),
        "last_in": dict(est._gate._last_in), "fz_ref": float(est._fz_ref), "fz_seen": est._fz_seen,
        "ema": est._ema_alpha, "dt_last": est._dt_last, "released": est.scale_released,
        "nis_seen": est._nis_seen, "rate": (rate.interval_s, rate._n, rate._t_last),
        "q_att": None if est._q_att is None else est._q_att.tolist(),
        "w_rot": None if est._w_rot is None else est._w_rot.tolist(), "rates": est._rates.tolist(),
        "hist": hist, "wind": est.wind_ned.tolist(), "wind_cov": est.wind_cov.tolist(),
    }  # fmt: skip


@pytest.mark.parametrize("seed", [0, 1])
def test_batch_equals_the_per_sample_calls(seed: int) -> None:
    s = _stream(seed)
    ref, fast = _kept(_per_sample(s)), _kept(_batched(s))
    for key in ref:
        assert fast[key] == ref[key], f"{key} differs between imu_batch and the per-sample calls"
    # The stream did exercise what it was built to: the filter ran, and every kind of bad sample was refused.
    rejected = ref["rejected"]
    assert isinstance(rejected, dict) and isinstance(ref["accepted"], dict)
    assert ref["accepted"]["imu"] > 700
    for reason in ("imu:bad_time", "imu:duplicate_or_out_of_order", "imu:bad_value", "attitude:bad_value",
                   "rotors:duplicate_or_out_of_order", "rotors:bad_value"):  # fmt: skip
        assert rejected.get(reason, 0) >= 1, f"the stream has no {reason}"
