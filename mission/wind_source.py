"""Where a strategy's wind information comes from: ``estimated``, ``oracle`` or ``none``.

- ``estimated``: the paper's UKF wind estimator (``estimator.ukf.WindEstimator``) fed in
  lockstep with the simulator's sensor samples (IMU, ESC rotor speeds, delayed GNSS velocity)
  and an AHRS-like attitude (truth rotated by a seeded Gauss-Markov error, the model of
  ``estimator.models`` and ``mission.runners.estimator_run``). This is what a real vehicle has.
- ``oracle``: the simulator's TRUE MEAN wind at the vehicle (``sim.wind.mean``), no
  turbulence, no error. For comparison only: no real vehicle has it.
- ``none``: no wind information at all (the strategies fall back to pure chemotaxis).

Every source returns a :class:`~mission.strategies.base.WindInfo` per strategy tick (or None
for ``none``). The upwind heading is the wind's from-direction through a causal Butterworth
low-pass (``estimator.direction.DirectionFilter`` on the unit vector, so no 0/360 jump) at the
strategy rate with the strategy's ``wind_filter_cutoff_hz`` -- the paper's heading command.
:class:`UpwindFilter` is that filtering alone, for runners that receive the wind another way
(a MAVSDK loop reading WIND_COV from the autopilot/companion).

Conventions: NED, SI; wind = air-mass velocity NED ([-5, 0, 0] blows from the north, upwind is
north); the upwind heading in rad equals the from-direction (0 = north, clockwise).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numba import njit

from estimator.direction import DirectionFilter, speed_direction
from estimator.ground_gate import GroundGate
from estimator.models import AhrsErrorModel, ahrs_attitudes, model_params
from estimator.ukf import EstimatorConfig, WindEstimator
from mission.strategies.base import WindInfo
from mission.strategies.params import CommonParams
from mission.wind_modes import INPROCESS_WIND_MODES
from sitl.simulation import T_QUAT, Simulation
from vehicle.params import VehicleParams


class UpwindFilter:
    """Wind vector (+ covariance) -> :class:`WindInfo` with the low-pass filtered upwind heading.

    Call :meth:`make` once per strategy tick (the filter is designed for ``params.rate_hz``).
    """

    def __init__(self, params: CommonParams) -> None:
        self.filter = DirectionFilter(params.wind_filter_cutoff_hz, params.rate_hz, int(params.wind_filter_order))
        self.min_speed = params.min_wind_m_s
        self.max_sigma_deg = params.wind_max_sigma_deg

    def make(self, wind_ned: np.ndarray, cov_ned: np.ndarray | None) -> WindInfo:
        """WindInfo for one tick; ``upwind_rad`` is NaN until a usable direction has arrived."""
        w = np.asarray(wind_ned, dtype=float)
        C = np.zeros((3, 3)) if cov_ned is None else np.asarray(cov_ned, dtype=float)
        speed, _, from_deg, from_sig_deg = speed_direction(w, C)
        # Below the minimum speed, or while the estimate has not converged (the filter starts
        # from zero wind with a large covariance), the direction is noise: do not feed it to
        # the low-pass, whose state would otherwise start from a wrong direction.
        usable = speed >= self.min_speed and from_sig_deg <= self.max_sigma_deg
        filtered = self.filter.update(from_deg) if usable else self.filter.value_deg
        return WindInfo(
            wind_ned=w.copy(), cov_ned=None if cov_ned is None else C,
            upwind_rad=math.radians(filtered) if math.isfinite(filtered) else math.nan,
            upwind_sigma_rad=math.radians(from_sig_deg),
        )


class WindSource(Protocol):
    """Wind information for the in-process runner, updated once per strategy tick."""

    mode: str

    def update(self, drained: dict[str, list]) -> WindInfo | None:
        """Consume the sensor samples drained from the simulation since the last tick."""
        ...


class NoWind:
    """``none``: no wind information."""

    mode = "none"

    def __init__(self, sim: Simulation, params: CommonParams) -> None:
        pass

    def update(self, drained: dict[str, list]) -> WindInfo | None:
        return None


class OracleWind:
    """``oracle``: the simulator's true mean wind at the vehicle (comparison only)."""

    mode = "oracle"

    def __init__(self, sim: Simulation, params: CommonParams) -> None:
        self.sim = sim
        self.upwind = UpwindFilter(params)

    def update(self, drained: dict[str, list]) -> WindInfo | None:
        sim = self.sim
        return self.upwind.make(sim.wind.mean(sim.t, sim.position), None)


class EstimatedWind:
    """``estimated``: the UKF wind estimator fed from the simulation's sensor samples.

    Needs a Simulation built with ``record_truth=True`` (only for the attitude measurement,
    which the simulator does not publish yet; consumed rows are dropped to bound memory).
    """

    mode = "estimated"

    def __init__(self, sim: Simulation, params: CommonParams, perturb_model: bool = False,
                 config: EstimatorConfig | None = None, ahrs: AhrsErrorModel | None = None,
                 imu_decimation: int = 1, model: VehicleParams | None = None) -> None:
        if sim.truth_log is None:
            raise ValueError("EstimatedWind needs Simulation(record_truth=True) for the attitude measurement")
        self.sim = sim
        seed = sim.seed
        base = sim.vehicle if model is None else sim.vehicle.with_model_of(model)
        self._model = model_params(base, seed, perturb_model)
        self._config = config
        self.estimator = WindEstimator(self._model, config)
        self._gate = GroundGate()
        self.restarts = 0
        self.ahrs = ahrs or AhrsErrorModel()
        self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xA4C5]))
        self._att_err = self._rng.normal(0.0, math.radians(self.ahrs.sigma_deg), 3)
        self._pending_gnss: list = []
        self._latency = sim.scenario.sensors.gnss.latency_s
        self._dt_imu = 1.0 / sim.scenario.sensors.imu.rate_hz
        self.upwind = UpwindFilter(params)
        if imu_decimation < 1:
            raise ValueError(f"imu_decimation = {imu_decimation}: must be >= 1")
        #: Feed the estimator the mean of every ``imu_decimation`` consecutive IMU samples
        #: (time-stamped at the last one): a 2:1 average halves the UKF cost (it runs one
        #: predict + update per sample) and averages out sensor noise.
        self.decimation = int(imu_decimation)
        self._sums = np.zeros((2, 3))  # the running sums of accelerometer and gyro samples (FRD)
        self._n_sum = 0
        # First-order Gauss-Markov attitude error (an autopilot EKF's slowly wandering error).
        self._ahrs_a, self._ahrs_c = self.ahrs.coefficients(self._dt_imu)

    def update(self, drained: dict[str, list]) -> WindInfo | None:
        sim = self.sim
        rows = sim.truth_log
        truth = np.concatenate(rows) if rows else np.zeros((0, 28))
        rows.clear()
        imu = drained["imu"]
        if len(imu) != truth.shape[0]:
            raise RuntimeError("IMU samples and truth rows out of step (drain once per tick)")
        esc = drained["esc"]
        self._pending_gnss.extend(drained["gnss"])
        action = self._gate.admit(self.sim.fc.on_ground)  # paused on the ground (estimator.ground_gate)
        if action == "pause":
            self._pending_gnss.clear()
            self._sums[:] = 0.0
            self._n_sum = 0
            return self.upwind.make(self.estimator.wind_ned, self.estimator.wind_cov)
        if action == "restart":
            self.estimator = WindEstimator(self._model, self._config)
            self.restarts += 1
        est = self.estimator
        if imu:
            self._feed(est, imu, esc, truth)
        return self.upwind.make(est.wind_ned, est.wind_cov)

    def _feed(self, est: WindEstimator, imu: list, esc: list, truth: np.ndarray) -> None:
        """Feed one tick's samples in time order: each IMU step (the mean of ``decimation`` samples, at
        the last one's time) after the ESC samples up to its time, with the AHRS attitude of that sample,
        then the GNSS fixes that have arrived by then. The AHRS error advances at every IMU sample. The
        steps between two GNSS fixes go to the filter in one call (:meth:`WindEstimator.imu_batch`)."""
        k = len(imu)
        t = [s[0] for s in imu]
        q = np.empty((k, 4))
        ahrs_attitudes(truth[:, T_QUAT], self._att_err, self._rng.standard_normal((k, 3)), self._ahrs_a,
                       self._ahrs_c, q)  # fmt: skip
        idx = np.empty(k, dtype=np.int64)
        means = np.empty((k, 2, 3))
        m, self._n_sum = group_means(np.array([s[1] for s in imu]), np.array([s[2] for s in imu]), self._sums,
                                     self._n_sum, self.decimation, idx, means)  # fmt: skip
        sel = idx[:m]
        ts, qs = np.array(t)[sel], q[sel]
        acc, gyr = np.ascontiguousarray(means[:m, 0]), np.ascontiguousarray(means[:m, 1])
        esc_t = np.array([e[0] for e in esc], dtype=float)
        esc_w = np.array([e[1] for e in esc], dtype=float) if esc else np.zeros((0, est.n_rotors))
        ei = j0 = 0
        pending, latency = self._pending_gnss, self._latency
        while j0 < m:
            # The steps up to the first at which a GNSS fix is due (one compiled call), then the fixes due: a fix
            # is delivered `latency` after its time of validity, as a receiver does.
            j1 = j0
            if pending:
                due = pending[0].t + latency
                while j1 < m - 1 and not due <= ts[j1] + 1e-9:
                    j1 += 1
            else:
                j1 = m - 1
            ei = est.imu_batch(ts[j0:j1 + 1], qs[j0:j1 + 1], acc[j0:j1 + 1], gyr[j0:j1 + 1], esc_t, esc_w, ei)
            ti = ts[j1]
            while pending and pending[0].t + latency <= ti + 1e-9:
                g = pending.pop(0)
                est.gnss_velocity(g.t, g.vel_ned)
            j0 = j1 + 1
        # ESC samples up to the tick's last IMU sample are in force at the next step; later ones are dropped.
        while ei < len(esc) and esc[ei][0] <= t[-1] + 1e-9:
            est.set_rotor_speeds(esc[ei][0], esc[ei][1])
            ei += 1


@njit(cache=True)
def group_means(acc: np.ndarray, gyr: np.ndarray, sums: np.ndarray, n_sum: int, d: int, idx: np.ndarray,
                means: np.ndarray) -> tuple[int, int]:  # fmt: skip
    """The means of every ``d`` consecutive IMU samples: ``acc``, ``gyr`` (k, 3; FRD, m/s^2 and rad/s)
    added in order to the running sums ``sums`` (2, 3; in place) of the ``n_sum`` samples carried
    over from the previous call. At each d-th sample: its index to ``idx``, the means to ``means``
    ((k, 2, 3): accelerometer, gyro), the sums cleared. Returns (steps written, samples carried)."""
    m = 0
    for k in range(acc.shape[0]):
        for i in range(3):
            sums[0, i] += acc[k, i]
            sums[1, i] += gyr[k, i]
        n_sum += 1
        if n_sum < d:
            continue
        idx[m] = k
        for i in range(3):
            means[m, 0, i] = sums[0, i] / n_sum
            means[m, 1, i] = sums[1, i] / n_sum
            sums[0, i] = 0.0
            sums[1, i] = 0.0
        n_sum = 0
        m += 1
    return m, n_sum


def make_wind_source(mode: str, sim: Simulation, params: CommonParams, imu_decimation: int = 1,
                     model: VehicleParams | None = None) -> WindSource:  # fmt: skip
    """The wind source for ``mode`` (``estimated``, ``oracle`` or ``none``); ``imu_decimation``:
    IMU samples averaged per estimator step in ``estimated`` mode; ``model``: the estimator's force model
    (a vehicle file's [model]; default the world's vehicle file's own)."""
    if mode == "estimated":
        return EstimatedWind(sim, params, imu_decimation=imu_decimation, model=model)
    if mode == "oracle":
        return OracleWind(sim, params)
    if mode == "none":
        return NoWind(sim, params)
    raise ValueError(f"wind mode {mode!r}: choose one of {', '.join(INPROCESS_WIND_MODES)}")
