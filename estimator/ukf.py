"""The paper's Bayesian wind estimator (Eq. 49-53): an unscented Kalman filter on the rotor model.

Conventions (the whole project's):
- SI units; world frame NED; body frame FRD; attitude quaternion [w, x, y, z] rotates FRD
  vectors into NED (``R = quat_to_dcm(q)``, ``v_ned = R v_frd``).
- WIND = AIR-MASS VELOCITY IN NED: a 10 m/s wind from the north is [-10, 0, 0].
  Airspeed = ground velocity - wind. (The paper adds its wind to the ground velocity, so its
  V_w is the negative of ours.)
- Directions are FROM-directions in degrees, 0 = from north, 90 = from east.

State x: [u, v, w] ground velocity in body axes (FRD, m/s), [W_n, W_e, W_d] wind (NED,
m/s), a force scale s (dimensionless, 1 = nominal; ``uncalibrated`` preset), accelerometer
biases on the body axes in ``bias_axes`` (FRD, m/s^2; ``calibrated`` preset: b_z only).
Inputs (held between their samples): attitude q, body rates (gyro), rotor speeds.
Process model (Eq. 49, 53), per step dt:
    v_air  = v_body - R^T W
    F      = rotor_wrench(v_air, rates, Omega, 0, p)[0:3]           (rotor force, FRD, N)
    f      = [s F_x / m, s F_y / m, F_z / m + (s - 1) fz_ref]        (specific force, FRD)
    v_body += dt (f + R^T [0, 0, g] - rates x v_body)
    W_n, W_e, s, b : random walks;  W_d : Ornstein-Uhlenbeck (mean-reverting to 0) or random walk
Measurements, each at its own rate (asynchronous updates):
    accelerometer   h = f(v_air) + b     (FRD specific force, every IMU sample)
    GNSS velocity   h = R v_body         (NED, at the sample's time of validity, see below)

Force scale (model error). At hover a constant vertical wind and a constant force-model
error (a mass known to a few %, thrust coefficients, accelerometer z bias) change the
measured specific force alike; vertical turbulence is zero-mean over tens of seconds, a model
error is constant, so with a mean-reverting W_d the constant part goes to s. s = m_model /
m_true for a mass error and then corrects the horizontal drag too. Three guards keep it from
soaking up wind: (1) its gain uses only the body-z accelerometer innovation (the horizontal
axes cannot tell a drag scale from a wind change); (2) the z correction multiplies the
low-passed measured z specific force ``fz_ref``, not the instantaneous thrust, so the fast
thrust fluctuations (whose gain the 50 Hz held ESC samples distort) carry no information on
it; (3) it is held at 1 through the cold start and frozen while and shortly after a
transient detector (low-passed normalized innovation) fires; the detector also raises the
wind process noise so the wind takes a step quickly.

Reported covariance: the filter's plus a model-error term (``model_error_cov``) for the
coefficient errors the scale cannot absorb, so that the +-2 sigma band stays honest when the
model is wrong.

The force model is the simulator's own ``vehicle.rotor_model.rotor_wrench`` (called from the
numba kernels here), so the estimator and the simulator cannot drift apart; the parameter
array may be exact or perturbed (``VehicleParams.perturbed``) to show what model error costs.

GNSS latency: a fix is valid ``latency`` seconds before it arrives. The filter keeps a short
history of its own NED velocity mean; the fix is moved forward to "now" by adding the change
of that mean since the time of validity (innovation = z + (v_now - v_then) - R v_body). This
is exact when the prediction over the delay is right and costs one lookup; it avoids
re-running the filter from a stored past state.

Bad input (non-finite, outside physical limits, duplicate or out-of-order timestamps) is
rejected before it touches the state and counted in :attr:`WindEstimator.rejected`. Gaps
are bridged by prediction only (covariance grows), in sub-steps of at most ``max_step_s``.

The class is plain, synchronous and deterministic: no I/O, no threads, no randomness.

Implementation: the unscented filter of filterpy (``UnscentedKalmanFilter`` with
``MerweScaledSigmaPoints``), written out as numba kernels over the filter's small arrays
(``sigma_kernels``, ``step_kernels``): one IMU step is one compiled call (``step_kernels.accel_step``:
prediction, accelerometer update, transient detector). filterpy is the reference:
``tests/test_estimator_reference.py`` runs both on the same data.

Files: this module is the filter (state, inputs, clocks, GNSS update and delay);
``estimator.config`` its tuning and presets, ``estimator.model_kernels`` the force model,
``estimator.step_kernels`` / ``estimator.sigma_kernels`` the unscented arithmetic and the
transient detector (numba),
``estimator.gating`` the input checks, ``estimator.outputs`` the estimate.
"""

from __future__ import annotations

import math
from collections import Counter, deque

import numpy as np

from estimator import imu_batch
from estimator.config import PRESETS, EstimatorConfig
from estimator.direction import DirectionFilter
from estimator.gating import InputGate
from estimator.imu_rate import ImuRate
from estimator.outputs import EstimatorOutputs, WindEstimate
from estimator.sigma_kernels import apply_gain, merwe_weights
from estimator.step_kernels import D_COUNT, D_LEFT, D_Q_GAIN, Work, accel_step, detector, predict, velocity_innovation
from vehicle.frames import quat_to_dcm
from vehicle.params import P_G, P_WMAX, VehicleParams

__all__ = ["PRESETS", "EstimatorConfig", "WindEstimate", "WindEstimator"]


class WindEstimator(EstimatorOutputs):
    """Wind UKF with asynchronous inputs. Feed samples in time order; read :meth:`estimate`.

    Args:
        params: vehicle parameters the force model uses (exact or ``perturbed``).
        config: tuning, see :class:`EstimatorConfig` (default: the preset the vehicle file calls for,
            :meth:`EstimatorConfig.for_vehicle`).

    Usage::

        est = WindEstimator(load_vehicle())
        est.set_attitude(t, q)            # body->NED quaternion [w, x, y, z]
        est.set_rotor_speeds(t, omega)    # rad/s (ESC telemetry or rpm_free model)
        est.imu(t, accel_frd, gyro_frd)   # predict to t, update with the specific force
        est.gnss_velocity(t_valid, v_ned) # update with a (delayed) NED velocity
        e = est.estimate()                # WindEstimate
    """

    def __init__(self, params: VehicleParams, config: EstimatorConfig | None = None) -> None:
        self.config = cfg = config or EstimatorConfig.for_vehicle(params)
        self.n_rotors = params.n_rotors
        self.params = params
        self._p = params.as_array()
        n = 6
        self._i_scale = -1  # index of the force-scale state, -1 = none
        self._bias_idx = np.full(3, -1, dtype=np.int64)  # state index of each body-axis accel bias, -1 = none
        P0 = [cfg.vel_sigma0_m_s**2] * 3 + [cfg.wind_sigma0_m_s**2] * 3
        q = list(np.square(cfg.vel_walk)) + list(np.square(cfg.wind_walk))
        x0 = [0.0] * 6
        if cfg.scale_state:
            self._i_scale = n
            n += 1
            P0.append(1e-12)  # held until released, see EstimatorConfig.scale_hold_s
            q.append(0.0)
            x0.append(1.0)
        for axis in sorted(set(cfg.bias_axes)):
            if axis not in (0, 1, 2):
                raise ValueError(f"bias_axes: body axis {axis} is not 0, 1 or 2")
            self._bias_idx[axis] = n
            n += 1
            P0.append(cfg.bias_sigma0_m_s2**2)
            q.append(cfg.bias_walk_m_s2**2)
            x0.append(0.0)
        self.n = n
        self._Wm, self._Wc, self._c = merwe_weights(n, cfg.alpha, cfg.beta, cfg.kappa)
        self._work = w = Work(n)
        self._w = (w.sig, w.sig_f, w.L, w.x_new, w.P_new)  # accel_step's scratch
        m3 = w.meas[3]
        self._m3 = (m3.S, m3.Pxz, m3.y, m3.K, m3.Lz)
        self.x = np.array(x0, dtype=float)  # state mean (see the module docstring)
        self.P = np.diag(np.array(P0, dtype=float))  # state covariance
        self._q_density = np.array(q)
        self._R_accel = np.diag(np.square(cfg.accel_noise_m_s2))
        self._R_gnss = np.diag(np.square(cfg.gnss_vel_noise_m_s))
        self.t: float | None = None  # filter time, s
        self._t_first: float | None = None  # time of the first prediction, s
        self.scale_released = not cfg.scale_state
        self._fz_ref = -float(self._p[P_G])  # low-passed measured body-z specific force, m/s^2
        self._fz_seen = False
        self._ema_alpha = 1.0
        # The transient detector's state and settings (step_kernels.watch_innovation).
        self._det, self._det_cfg = detector(cfg.transient_threshold, cfg.transient_max_s, cfg.transient_hold_s,
                                            cfg.transient_wind_q_gain)  # fmt: skip
        self._dt_last = 0.0
        self._bias_cov: tuple[float, np.ndarray] | None = None  # EstimatorOutputs.unseen_bias_cov's cache
        self.heading_sigma_rad = 0.0  # stated 1-sigma of the attitude's heading (estimator.compass), rad
        self.imu_rate = ImuRate(cfg.accel_noise_rate_hz)  # the accelerometer variance per sample at the stream's rate
        # The last successful accelerometer innovation and its covariance (last_nis), and whether there was one.
        self._nis = (np.zeros(3), np.zeros((3, 3)))
        self._nis_seen = False
        self._R: np.ndarray | None = None  # attitude DCM body->NED
        self._q_att: np.ndarray | None = None
        self._rates = np.zeros(3)
        self._w_rot: np.ndarray | None = None
        self._hist: deque[tuple[float, np.ndarray, np.ndarray]] = deque()  # (t s, R body->NED, body velocity m/s)
        self._gate = InputGate()
        self.rejected: Counter[str] = self._gate.rejected
        self.accepted: Counter[str] = Counter()
        self.direction = DirectionFilter(cfg.direction_cutoff_hz, cfg.direction_rate_hz, cfg.direction_order)
        self._dir_filtered = float("nan")

    # ------------------------------------------------------------------ inputs
    def _reject(self, reason: str) -> bool:
        """Count a rejected input (adapters use it for what they decode themselves)."""
        return self._gate.reject(reason)

    def set_attitude(self, t: float, q_wxyz: np.ndarray) -> bool:
        """Attitude quaternion [w, x, y, z], body FRD -> NED (from the AHRS/EKF). Held until the next."""
        q = self._gate.attitude(t, q_wxyz)
        if q is None:
            return False
        self._q_att = q
        self._R = quat_to_dcm(q)
        self.accepted["attitude"] += 1
        return True

    def set_heading_sigma(self, sigma_rad: float) -> None:
        """The 1-sigma (rad) of the attitude's heading to state in the wind covariance (``heading_cov``);
        0, the default, states none (the filter's own noise model carries an AHRS's usual error)."""
        self.heading_sigma_rad = max(float(sigma_rad), 0.0) if math.isfinite(sigma_rad) else 0.0

    def set_rates(self, t: float, rates_frd: np.ndarray) -> bool:
        """Body rates (FRD, rad/s) when they come separately from the IMU (e.g. MAVLink ATTITUDE)."""
        w = self._gate.rates(t, rates_frd)
        if w is None:
            return False
        self._rates = w
        return True

    def set_rotor_speeds(self, t: float, w_rot: np.ndarray) -> bool:
        """Rotor speeds (rad/s, rotor order of ``vehicle.rotor_model``). Held until the next sample."""
        w = self._gate.rotors(t, w_rot, float(self._p[P_WMAX]), self.n_rotors)
        if w is None:
            return False
        self._w_rot = w
        self.accepted["rotors"] += 1
        return True

    @property
    def span_s(self) -> float:
        """Seconds of data the filter has run over since its cold start (0 before it starts)."""
        return 0.0 if self._t_first is None or self.t is None else float(self.t - self._t_first)

    @property
    def ready(self) -> bool:
        """True once attitude and rotor speeds have been received (the model needs both)."""
        return self._R is not None and self._w_rot is not None

    def missing_inputs(self) -> list[str]:
        """The held inputs not received yet: ``attitude``, ``rotor speeds`` (empty when ready)."""
        return [name for name, v in (("attitude", self._R), ("rotor speeds", self._w_rot)) if v is None]

    def imu(self, t: float, accel_frd: np.ndarray, gyro_frd: np.ndarray | None = None) -> bool:
        """IMU sample at time t: predict to t, then update with the specific force (FRD, m/s^2).

        ``gyro_frd`` (rad/s) becomes the rates input; pass None when rates come via set_rates.
        Returns False (and counts why) when the sample was rejected; the state is untouched then.
        """
        checked = self._gate.imu(t, accel_frd, gyro_frd, self.t, self.ready)
        if checked is None:
            return False
        a, g = checked
        if g is not None:
            self._rates = g.copy()
        R, w_rot = self._R, self._w_rot
        assert R is not None and w_rot is not None  # the gate checked ``ready``
        n_steps, dt, decay = self._plan(t)
        fz_pred = self._fz_ref
        if self._fz_seen:
            self._fz_ref += min(1.0, self._ema_alpha * self.config.transient_tau_s / self.config.fz_ref_tau_s) * (
                a[2] - self._fz_ref
            )
        else:
            self._fz_ref, self._fz_seen = float(a[2]), True
        f = self.imu_rate.factor(t)
        failed, status = accel_step(
            self.x, self.P, a, self._R_accel if f == 1.0 else self._R_accel * f, R, self._rates, w_rot,
            self._p, n_steps, dt, decay, fz_pred, self._fz_ref, self._q_density, self._i_scale, self._bias_idx,
            self.scale_released, self._Wm, self._Wc, self._c, self._det, self._det_cfg, self._ema_alpha,
            min(1.0, self._dt_last / self.config.transient_baseline_tau_s), self._dt_last, self._w, self._m3, self._nis,
        )  # fmt: skip
        self._nis_seen = self._nis_seen or status != 1
        if failed or status:
            self.rejected["numerical"] += failed + (status != 0)
        self.accepted["imu"] += 1
        self._record_history()
        return True

    def imu_batch(self, ts: np.ndarray, qs: np.ndarray, accel: np.ndarray, gyro: np.ndarray, rotor_t: np.ndarray,
                  rotor_w: np.ndarray, ri: int) -> int:  # fmt: skip
        """IMU steps at times ``ts`` (m,) s in one compiled call: for each, the rotor speed samples ``rotor_w``
        (E, N; rad/s) at times ``rotor_t`` (E,) from index ``ri`` up to its time (:meth:`set_rotor_speeds`),
        the attitude ``qs`` (m, 4; :meth:`set_attitude`), then the IMU sample ``accel``, ``gyro`` (m, 3; FRD,
        m/s^2 and rad/s; :meth:`imu`). The same checks, counts and state as those calls, bit for bit
        (:mod:`estimator.imu_batch`). Returns the index of the first rotor speed sample not taken."""
        return imu_batch.feed(self, ts, qs, accel, gyro, rotor_t, rotor_w, ri)

    def gnss_velocity(self, t_valid: float, vel_ned: np.ndarray) -> bool:
        """NED ground velocity (m/s) valid at ``t_valid`` (s; may lie up to gnss_history_s in the past).

        ``vel_ned`` has 3 components, or 2 (north, east) for receivers without a vertical
        velocity (MAVLink GPS_RAW_INT): then only the horizontal components update.
        """
        v = self._gate.velocity(t_valid, vel_ned)
        if v is None:
            return False
        nz = v.shape[0]
        if not self.ready or self.t is None:
            return self._reject("gnss:not_ready")
        if t_valid > self.t + self.config.max_step_s:
            # A fix from the future (clock mismatch): bring the filter up to it first.
            self.predict_to(t_valid)
        shift = np.zeros(3)
        if t_valid < self.t:
            past = self._history_at(t_valid)
            if past is None:
                return self._reject("gnss:stale")
            shift = self._R @ self.x[0:3] - past
        self._gate.mark("gnss", t_valid)
        self._velocity_update(v + shift[:nz], self._R_gnss[:nz, :nz])
        self.accepted["gnss"] += 1
        return True

    # ------------------------------------------------------------------ filter core
    def predict_to(self, t: float) -> None:
        """Predict the state to time t (s) with the held inputs; covariance grows over gaps."""
        n, dt, decay = self._plan(t)
        R, w_rot = self._R, self._w_rot
        if n and R is not None and w_rot is not None:
            failed = predict(
                self.x, self.P, n, dt, R, self._rates, w_rot, self._p, decay, self._i_scale,
                self._fz_ref, self._q_density, self._det[D_Q_GAIN], self._Wm, self._Wc, self._c, *self._w,
            )  # fmt: skip
            if failed:
                self.rejected["numerical"] += failed

    def _plan(self, t: float) -> tuple[int, float, float]:
        """Advance the filter time to t (s) and its clocks (scale release, transient hold, low-pass weight);
        returns the prediction to run: (sub-steps, each one's length in s, the vertical wind's decay over
        one). No sub-steps on the first sample, without a forward span or before the inputs are held."""
        if self.t is None:
            self.t = self._t_first = t
            return 0, 0.0, 1.0
        if not self.scale_released:
            self._maybe_release_scale(t)
        span = t - self.t
        if span > 0.0:
            self._det[D_LEFT] -= span
            self._dt_last = span
            self._ema_alpha = min(1.0, span / self.config.transient_tau_s)
        span = min(t - self.t, self.config.max_gap_s)
        self.t = max(self.t, t)
        if not (span > 0.0 and self._R is not None and self._w_rot is not None):
            return 0, 0.0, 1.0
        n = max(1, math.ceil(span / self.config.max_step_s - 1e-9))
        dt = span / n
        tau = self.config.vertical_wind_tau_s
        return n, dt, math.exp(-dt / tau) if tau else 1.0

    def _maybe_release_scale(self, t: float) -> None:
        cfg = self.config
        if self._t_first is None:
            return
        held = t - self._t_first
        if held < cfg.scale_hold_s:
            return
        # The horizontal wind converges whatever the model error (the vertical may not: the
        # scale is what fixes it); release anyway after three hold times.
        if max(self.P[3, 3], self.P[4, 4]) > cfg.scale_release_wind_sigma_m_s**2 and held < 3.0 * cfg.scale_hold_s:
            return
        i = self._i_scale
        self.P[i, :] = 0.0
        self.P[:, i] = 0.0
        self.P[i, i] = cfg.scale_sigma0**2
        self._q_density[i] = cfg.scale_walk_per_sqrt_s**2
        self.scale_released = True

    def _velocity_update(self, z: np.ndarray, Rn: np.ndarray) -> None:
        """Unscented update with a NED velocity ``z`` (m/s, 2 or 3 components; noise ``Rn``) with sigma
        points of the current (x, P); the force scale does not learn from it (its gain row is zero).

        The covariance is updated in the general form P - K Pxz^T - Pxz K^T + K S K^T when the scale's
        row is restricted. A numerical failure leaves (x, P) as they were (1e-6 added to the diagonal of P)
        and is counted. The accelerometer update is ``step_kernels.accel_step`` (in :meth:`imu`)."""
        Rm = self._R
        if Rm is None:  # not ready: callers check first
            return
        w = self._work
        m = w.meas[z.shape[0]]
        ok = velocity_innovation(
            self.x, self.P, z, Rn, Rm, self._Wm, self._Wc, self._c, w.sig, w.L, m.h, m.S, m.Pxz, m.y, m.K, m.Lz
        )
        if ok:
            i = self._i_scale
            if i >= 0:
                m.K[i, :] = 0.0
            ok = apply_gain(self.x, self.P, m.K, m.S, m.Pxz, m.y, i >= 0, w.x_new, w.P_new)
        if not ok:
            self.P[np.diag_indices(self.n)] += 1e-6
            self.rejected["numerical"] += 1

    @property
    def transients(self) -> int:
        """Times the transient detector fired (``step_kernels.watch_innovation``)."""
        return int(self._det[D_COUNT])

    @property
    def last_nis(self) -> float:
        """The last accelerometer update's normalized innovation squared y' S^-1 y (chi-square with 3 degrees
        of freedom when the model and the noise are right; NaN before the first): estimator.model_fit's
        running innovation test reads it. Computed when read."""
        if not self._nis_seen:
            return math.nan
        y, S = self._nis
        return float(y @ np.linalg.solve(S, y))

    @property
    def rotor_speeds(self) -> np.ndarray | None:
        """The rotor speeds in force (rad/s, the last accepted sample)."""
        return self._w_rot

    def wind_sigma_h(self) -> float:
        """The larger horizontal wind 1-sigma of the filter (m/s): how far it has converged."""
        return float(math.sqrt(max(self.P[3, 3], self.P[4, 4])))

    def airspeed_body(self) -> np.ndarray | None:
        """The filter's airspeed (FRD, m/s): body ground velocity minus the wind in body axes; None before
        it has an attitude."""
        if self._R is None:
            return None
        return np.asarray(self.x[0:3] - self._R.T @ self.x[3:6])

    def _record_history(self) -> None:
        # The NED velocity R @ x[0:3] is formed when an entry is read (_history_at: a few per GNSS fix),
        # not at every step; the attitude matrix is never changed in place (set_attitude makes a new one).
        if self._R is None or self.t is None:
            return
        self._hist.append((self.t, self._R, self.x[0:3].copy()))
        horizon = self.t - self.config.gnss_history_s
        while self._hist and self._hist[0][0] < horizon:
            self._hist.popleft()

    def _history_at(self, t: float) -> np.ndarray | None:
        """NED velocity mean at time t, linearly interpolated from the history."""
        h = self._hist
        if not h or t < h[0][0]:
            return None
        prev = h[0]
        for item in h:
            if item[0] >= t:
                t0, R0, b0 = prev
                t1, R1, b1 = item
                if t1 <= t0:
                    return R1 @ b1
                v0, v1 = R0 @ b0, R1 @ b1
                a = (t - t0) / (t1 - t0)
                return v0 + a * (v1 - v0)
            prev = item
        return h[-1][1] @ h[-1][2]
