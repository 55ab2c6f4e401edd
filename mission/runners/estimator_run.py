"""The wind estimator flown in lockstep on the simulator (``windseek estimate``): the sensor outputs feed it.

Per IMU sample (250 Hz, time order): the latest ESC rotor speeds are held (50 Hz), the
attitude measurement is set, then the IMU sample predicts and updates the filter. GNSS fixes
(10 Hz) are applied when they arrive, ``latency`` after their time of validity, as a real
receiver delivers them; the filter compensates the delay (see ``estimator.ukf``).

Attitude: the simulator has no attitude message yet. A flight controller's EKF delivers an
attitude with a slowly wandering error of a fraction of a degree, so the measurement here is
the true attitude rotated by a seeded first-order Gauss-Markov error (default 0.5 deg
1-sigma per axis, 20 s correlation time). Rates come from the (noisy, biased) gyro.

Frames and units: NED/FRD, SI; wind = air-mass velocity NED (see ``estimator.ukf``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from estimator.models import AhrsErrorModel, model_params
from estimator.rpm_free import MotorCommandModel
from estimator.ukf import EstimatorConfig, WindEstimator
from sitl.scenario import Scenario
from sitl.simulation import N_TRUTH, T_QUAT, T_ROTOR_CMD, T_TIME, T_WIND, Simulation
from vehicle.frames import quat_mul
from vehicle.params import VehicleParams


@dataclass
class RunLog:
    """Estimator outputs and truth at every IMU instant (arrays of length K, NED, m/s, deg)."""

    t: np.ndarray
    wind_est: np.ndarray  # (K, 3)
    wind_sigma: np.ndarray  # (K, 3), 1-sigma
    direction_deg: np.ndarray
    direction_sigma_deg: np.ndarray
    direction_filtered_deg: np.ndarray
    wind_true: np.ndarray  # (K, 3) air-mass velocity at the vehicle incl. turbulence
    us_per_step: float
    rejected: dict[str, int] = field(default_factory=dict)


class InProcessRunner:
    """Simulation + estimator in lockstep.

    Args:
        scenario: the scenario to fly.
        seed: simulator seed; the AHRS error and model perturbation derive from it too.
        perturb_model: estimator parameters perturbed inside the paper's confidence intervals.
        no_rpm: ignore ESC telemetry; rotor speeds implied by the motor commands (rpm_free).
        config: estimator tuning.
        ahrs: attitude measurement error model.
        model: the estimator's force model (a vehicle file's [model], e.g. an identified one); default the
            world's vehicle file's own.
    """

    def __init__(
        self,
        scenario: Scenario,
        seed: int | None = None,
        perturb_model: bool = False,
        no_rpm: bool = False,
        config: EstimatorConfig | None = None,
        ahrs: AhrsErrorModel | None = None,
        model: VehicleParams | None = None,
    ) -> None:
        self.sim = Simulation(scenario, seed=seed, record_truth=True)
        seed = self.sim.seed
        base = self.sim.vehicle if model is None else self.sim.vehicle.with_model_of(model)
        self.params = model_params(base, seed, perturb_model)
        self.estimator = WindEstimator(self.params, config)
        self.no_rpm = no_rpm
        self.motor = MotorCommandModel(self.params.motor_time_constant_s, self.params.rotor_speed_max_rad_s)
        self.ahrs = ahrs or AhrsErrorModel()
        self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xA4C5]))
        self._att_err = self._rng.normal(0.0, math.radians(self.ahrs.sigma_deg), 3)
        self._truth_idx = 0
        self._pending_gnss: list = []
        self._latency = scenario.sensors.gnss.latency_s
        self._log: list[np.ndarray] = []
        self._est_time = 0.0
        self._steps = 0
        self._seen = 0

    def _attitude_measurement(self, q_true: np.ndarray, dt: float) -> np.ndarray:
        a = math.exp(-dt / self.ahrs.tau_s)
        sig = math.radians(self.ahrs.sigma_deg)
        self._att_err = a * self._att_err + math.sqrt(1.0 - a * a) * sig * self._rng.standard_normal(3)
        e = self._att_err
        dq = np.array([1.0, 0.5 * e[0], 0.5 * e[1], 0.5 * e[2]])
        q = quat_mul(q_true, dq / np.linalg.norm(dq))
        return q / np.linalg.norm(q)

    def run(self, duration_s: float | None = None, chunk_s: float = 0.02) -> RunLog:
        """Fly the scenario (or ``duration_s``) and return the log."""
        sim = self.sim
        end = sim.scenario.duration_s if duration_s is None else duration_s
        while sim.t < end - 1e-9:
            sim.run_until(min(end, sim.t + chunk_s))
            self._consume(sim.drain())
        return self.log()

    def _consume(self, out: dict[str, list]) -> None:
        sim = self.sim
        log = sim.truth_log
        if log is None:
            raise RuntimeError("the simulation records no truth (record_truth=False)")
        rows = log[self._truth_idx :]
        self._truth_idx = len(log)
        truth = np.concatenate(rows) if rows else np.zeros((0, N_TRUTH))
        esc = list(out["esc"])
        self._pending_gnss.extend(out["gnss"])
        est = self.estimator
        imu = out["imu"]
        if len(imu) != truth.shape[0]:
            raise RuntimeError("IMU samples and truth rows out of step")
        ei = 0
        dt_imu = 1.0 / sim.scenario.sensors.imu.rate_hz
        for k, (t, acc, gyr) in enumerate(imu):
            row = truth[k]
            q_meas = self._attitude_measurement(row[T_QUAT], dt_imu)
            c0 = time.perf_counter()
            if self.no_rpm:
                w = self.motor.update(t, row[T_ROTOR_CMD][: self.params.n_rotors])
                if w is not None:
                    est.set_rotor_speeds(t, w)
            else:
                while ei < len(esc) and esc[ei][0] <= t + 1e-9:
                    est.set_rotor_speeds(esc[ei][0], esc[ei][1])
                    ei += 1
            est.set_attitude(t, q_meas)
            est.imu(t, acc, gyr)
            while self._pending_gnss and self._pending_gnss[0].t + self._latency <= t + 1e-9:
                g = self._pending_gnss.pop(0)
                est.gnss_velocity(g.t, g.vel_ned)
            e = est.estimate()
            if self._seen >= 25:
                self._est_time += time.perf_counter() - c0
                self._steps += 1
            # The first steps load the numba kernels from their cache: not a per-step cost.
            self._seen += 1
            self._log.append(
                np.concatenate(
                    (
                        [row[T_TIME]],
                        e.wind_ned,
                        e.sigma_ned,
                        [e.direction_deg, e.direction_sigma_deg, e.direction_filtered_deg],
                        row[T_WIND],
                    )
                )
            )

    def log(self) -> RunLog:
        a = np.array(self._log) if self._log else np.zeros((0, 13))
        return RunLog(
            t=a[:, 0],
            wind_est=a[:, 1:4],
            wind_sigma=a[:, 4:7],
            direction_deg=a[:, 7],
            direction_sigma_deg=a[:, 8],
            direction_filtered_deg=a[:, 9],
            wind_true=a[:, 10:13],
            us_per_step=1e6 * self._est_time / max(self._steps, 1),
            rejected=dict(self.estimator.rejected),
        )
