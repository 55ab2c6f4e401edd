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
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field, replace

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from numba import njit

from estimator.direction import DirectionFilter, speed_direction
from vehicle.frames import quat_to_dcm
from vehicle.params import P_G, P_MASS, P_WMAX, VehicleParams
from vehicle.rotor_model import rotor_wrench

# Physical plausibility limits for raw inputs (beyond them a sample is a fault, not data).
ACCEL_LIMIT_M_S2 = 160.0  # 16 g, a typical accelerometer range
GYRO_LIMIT_RAD_S = 35.0  # 2000 deg/s
VELOCITY_LIMIT_M_S = 100.0
QUAT_NORM_TOL = 0.1


@njit(cache=True)
def _specific_force(
    x: np.ndarray, R: np.ndarray, rates: np.ndarray, w_rot: np.ndarray, p: np.ndarray, i_scale: int, fz_ref: float
) -> np.ndarray:
    """Model specific force (FRD, m/s^2) at state x: rotor forces over mass at the airspeed.

    With a force-scale state s = ``x[i_scale]`` (``i_scale >= 0``, dimensionless, 1 =
    nominal): s * F_x / m, s * F_y / m and F_z / m + (s - 1) * fz_ref, where ``fz_ref`` is the
    low-passed measured body-z specific force (m/s^2). To first order in s - 1 this is s * F / m
    (a mass error); the z correction leaves out the fast thrust fluctuations on purpose (see
    EstimatorConfig.scale_state).
    """
    W0, W1, W2 = x[3], x[4], x[5]
    v_air = np.empty(3)
    for i in range(3):
        # R^T W: the wind (NED) seen in body axes.
        v_air[i] = x[i] - (R[0, i] * W0 + R[1, i] * W1 + R[2, i] * W2)
    fm = rotor_wrench(v_air, rates, w_rot, np.zeros(4), p)
    im = 1.0 / p[P_MASS]
    out = np.empty(3)
    if i_scale >= 0:
        sc = x[i_scale]
        out[0] = fm[0] * im * sc
        out[1] = fm[1] * im * sc
        out[2] = fm[2] * im + (sc - 1.0) * fz_ref
    else:
        out[0] = fm[0] * im
        out[1] = fm[1] * im
        out[2] = fm[2] * im
    return out


@njit(cache=True)
def _process_batch(
    sigmas: np.ndarray,
    out: np.ndarray,
    dt: float,
    R: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    p: np.ndarray,
    decay_d: float,
    i_scale: int,
    fz_ref: float,
) -> None:
    """Propagate every sigma point by one Euler step of Eq. 49. Wind, scale and bias: random
    walks, except the vertical wind, multiplied by ``decay_d`` (Ornstein-Uhlenbeck, see
    EstimatorConfig; 1 = random walk)."""
    g = p[P_G]
    pr, qr, rr = rates[0], rates[1], rates[2]
    for k in range(sigmas.shape[0]):
        x = sigmas[k]
        f = _specific_force(x, R, rates, w_rot, p, i_scale, fz_ref)
        u, v, w = x[0], x[1], x[2]
        # Gravity in body axes is the third row of R (R^T [0, 0, g]); the rates x v term is
        # the rotation of the body axes the velocity is expressed in.
        du = f[0] + R[2, 0] * g - (qr * w - rr * v)
        dv = f[1] + R[2, 1] * g - (rr * u - pr * w)
        dw = f[2] + R[2, 2] * g - (pr * v - qr * u)
        out[k, :] = x
        out[k, 0] = u + dt * du
        out[k, 1] = v + dt * dv
        out[k, 2] = w + dt * dw
        out[k, 5] = x[5] * decay_d


@njit(cache=True)
def _accel_batch(
    sigmas: np.ndarray,
    R: np.ndarray,
    rates: np.ndarray,
    w_rot: np.ndarray,
    p: np.ndarray,
    i_scale: int,
    bias_idx: np.ndarray,
    fz_ref: float,
) -> np.ndarray:
    """Accelerometer measurement model at every sigma point: f(v_air) (with the force scale)
    + bias; ``bias_idx[i]`` is the state index of the body-axis-i bias, -1 = no bias state."""
    n = sigmas.shape[0]
    out = np.empty((n, 3))
    for k in range(n):
        f = _specific_force(sigmas[k], R, rates, w_rot, p, i_scale, fz_ref)
        for i in range(3):
            j = bias_idx[i]
            out[k, i] = f[i] + (sigmas[k, j] if j >= 0 else 0.0)
    return out


@dataclass(frozen=True)
class EstimatorConfig:
    """Tuning of the wind UKF. Noise values are 1-sigma; random-walk densities are per sqrt(s).

    The accelerometer noise includes the model error the filter must tolerate (ESC noise on
    the thrust, rotor speeds held between ESC samples), hence larger than the sensor's own.

    Two presets; pick by whether the vehicle was identified (see :data:`PRESETS`):

    - :meth:`uncalibrated` (= ``EstimatorConfig()``, the default everywhere a preset is not
      chosen, including the MAVLink companion ``windseek estimator`` and the mission runners):
      the force model is only known to a few % (mass, thrust coefficients), so a force-scale
      state takes the constant part of the force error and the vertical wind is mean-reverting
      (a steady updraft is read partly as model error).
    - :meth:`calibrated`: mass and Eq. 46 coefficients identified for this vehicle, as the
      paper assumes. No force-scale state; the vertical wind is a random walk as Eq. 53; a
      body-z accelerometer-bias state with the sensor's turn-on 1-sigma (a datasheet value)
      as prior takes the constant z offset, which otherwise leaks into the vertical wind and,
      through the airspeed terms of the thrust, into the horizontal wind.
    """

    accel_noise_m_s2: tuple[float, float, float] = (0.12, 0.12, 0.25)
    gnss_vel_noise_m_s: tuple[float, float, float] = (0.08, 0.08, 0.1)
    #: Unmodelled acceleration on the body velocity (attitude error x g, model error), m/s^2/sqrt(Hz).
    vel_walk: tuple[float, float, float] = (0.4, 0.4, 0.6)
    #: Wind random walk (Eq. 53), m/s per sqrt(s): sets how fast turbulence can be followed.
    wind_walk: tuple[float, float, float] = (1.5, 1.5, 1.5)
    #: Correlation time (s) of the vertical wind, modelled as first-order Gauss-Markov
    #: (Ornstein-Uhlenbeck) around zero instead of a random walk; None = random walk (Eq. 53
    #: as printed). Why: at hover a constant vertical wind and a constant error of the force
    #: model (mass, thrust coefficients, accelerometer z bias) change the measured specific
    #: force the same way; vertical wind in turbulence is zero-mean over tens of seconds,
    #: a model error is constant, so the mean-reverting wind lets the force-scale state
    #: take the constant part. Stationary 1-sigma = wind_walk[2] * sqrt(tau / 2).
    vertical_wind_tau_s: float | None = 3.0
    #: Force-scale state s (dimensionless, 1 = nominal): the model specific force is
    #: s * F(v_air) / m on all three body axes, i.e. s = m_model / m_true when the mass is
    #: wrong. Observable through the vertical axis (the hover thrust must carry the weight),
    #: it then corrects the horizontal drag too. Prior 1-sigma and random walk per sqrt(s).
    scale_state: bool = True
    scale_sigma0: float = 0.05
    scale_walk_per_sqrt_s: float = 3e-4
    #: The scale is held at its prior mean (zero variance) during the cold start and released
    #: with ``scale_sigma0`` once the filter has run ``scale_hold_s`` and the horizontal wind
    #: 1-sigma is below ``scale_release_wind_sigma_m_s`` (at the latest after 3 hold times):
    #: while the wind is still unknown the filter would explain the large early innovations
    #: with the scale and lock it in. Held too long, the opposite happens: the constant force
    #: error (a few % of the weight, ~0.5 m/s per % in vertical-wind units) goes to the
    #: vertical wind, which the cold start drives past the identified vertical-airspeed domain
    #: (the thrust's tanh saturation, 3 m/s), where the thrust hardly depends on it; it comes
    #: back only through the mean reversion, and the scale, once released, converges within
    #: a few seconds to whatever offset is left and then moves only by its slow random walk,
    #: so that offset stays in the vertical wind for the whole flight (perturbed paper-s1,
    #: seed 109, 3 % mass error: scale 0.984 after release against 0.965 needed, vertical
    #: wind 1-2 m/s off until the end). 1.5 s instead of 3 s (perturbed paper-s1/-s2, tuning
    #: seeds 100-109: vertical 1-s RMSE 1.11 -> 0.92 and 0.76 -> 0.61 m/s, horizontal 0.436
    #: -> 0.402 and 0.284 -> 0.252; 8 s: vertical 2.2 on paper-s1). Cost: in the first
    #: seconds after a cold start the early scale takes part of the transient (steady wind,
    #: exact model, 4-8 s: horizontal ~0.05 m/s worse).
    scale_hold_s: float = 1.5
    scale_release_wind_sigma_m_s: float = 1.0
    #: Transient detector (see WindEstimator._watch_innovation): time constant (s) of the
    #: low-passed normalized accelerometer innovation, its threshold, and how long (s) the
    #: force scale stays frozen after it fires.
    transient_tau_s: float = 0.25
    fz_ref_tau_s: float = 1.0  # low-pass (s) of the measured body-z specific force the scale multiplies
    transient_threshold: float = 0.5
    transient_hold_s: float = 3.0
    #: A detector firing longer than this (s) without a break is model error, not a step.
    transient_max_s: float = 2.0
    transient_baseline_tau_s: float = 10.0  # slow baseline the low-passed innovation is compared with
    #: While the detector fires, the wind random-walk variance is multiplied by this (the wind
    #: follows a step faster instead of the other states soaking it up).
    transient_wind_q_gain: float = 10.0
    #: Model error added to the reported wind covariance (see WindEstimator.model_error_cov):
    #: relative error of the horizontal drag after the force scale (the Table 5 95 % intervals
    #: give about 1-2 % at 10 m/s, half of it a bias the 2-sigma band must cover), and an
    #: absolute vertical-wind term, m/s.
    model_error_rel_h: float = 0.008
    model_error_d_m_s: float = 0.4
    #: Body axes (0 = x, 1 = y, 2 = z, FRD) with an accelerometer-bias state. None by default:
    #: at a constant heading a horizontal bias is indistinguishable from a wind change, and the
    #: z bias from the force scale; the calibrated preset estimates the z bias alone.
    bias_axes: tuple[int, ...] = ()
    bias_walk_m_s2: float = 0.002  # per sqrt(s)
    bias_sigma0_m_s2: float = 0.05
    #: Initial state: zero wind with a large covariance (no prior, as in the paper).
    wind_sigma0_m_s: float = 10.0
    vel_sigma0_m_s: float = 2.0
    #: Merwe scaled sigma points.
    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0
    max_step_s: float = 0.02  # longest single prediction step (gaps are bridged in sub-steps)
    max_gap_s: float = 30.0  # longer gaps: predict at most this long (the covariance is huge by then)
    gnss_history_s: float = 1.0  # how far back a GNSS time of validity may lie
    direction_cutoff_hz: float = 0.2  # Butterworth low-pass on the wind direction (heading command)
    direction_order: int = 2
    direction_rate_hz: float = 250.0  # nominal output rate the Butterworth is designed for

    @classmethod
    def uncalibrated(cls, **overrides) -> EstimatorConfig:
        """Vehicle not identified (mass and force model known to a few %): force-scale state,
        mean-reverting vertical wind. The default, and the right choice for a real vehicle
        unless it was identified."""
        return replace(cls(), **overrides)

    @classmethod
    def calibrated(cls, **overrides) -> EstimatorConfig:
        """Vehicle mass and Eq. 46 model identified (the paper's assumption): no force-scale
        state, random-walk vertical wind (Eq. 53), body-z accelerometer bias state (prior
        0.02 m/s^2 1-sigma, the IMU's turn-on bias; random walk 5e-4 m/s^2/sqrt(s), its
        in-run drift), smaller model-error term on the reported vertical covariance.

        Body-z velocity random walk 0.1 m/s^2/sqrt(Hz) instead of 0.6. Why: with an exact
        force model the unmodelled body-z acceleration is only the attitude error projected on
        the tilted z axis (g sin(tilt) delta, ~0.02 m/s^2 for 0.5 deg at 15 deg tilt, correlated
        over tens of seconds) and the 50 Hz held rotor speeds (~0.02 m/s^2/sqrt(Hz)); 0.6
        (sized for the uncalibrated model's coefficient errors) made the GNSS vertical velocity
        nearly useless for pinning the thrust, so the (vertical wind, z bias) pair, which the
        accelerometer alone cannot separate at hover, wandered (z bias -0.07 m/s^2 against a
        true ~0, dragging the vertical and, through the thrust's airspeed terms, the horizontal
        wind). The horizontal axes keep 0.4: there the attitude error times g (~0.09 m/s^2)
        is a real unmodelled acceleration."""
        base = replace(
            cls(),
            vel_walk=(0.4, 0.4, 0.1),
            scale_state=False,
            vertical_wind_tau_s=None,
            bias_axes=(2,),
            bias_sigma0_m_s2=0.02,
            bias_walk_m_s2=5e-4,
            model_error_d_m_s=0.25,
        )
        return replace(base, **overrides)

    @classmethod
    def preset(cls, name: str, **overrides) -> EstimatorConfig:
        """The preset called ``name`` (one of :data:`PRESETS`)."""
        if name not in PRESETS:
            raise ValueError(f"unknown estimator calibration {name!r}; choose from {', '.join(PRESETS)}")
        return getattr(cls, name)(**overrides)


#: Preset names of :meth:`EstimatorConfig.preset`: whether the vehicle's mass and force model
#: were identified. Real vehicles default to ``uncalibrated``.
PRESETS = ("calibrated", "uncalibrated")


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


class _UKF(UnscentedKalmanFilter):
    """filterpy's UKF with the two Python loops over sigma points replaced by array code.

    ``compute_process_sigmas`` runs the numba process kernel over all sigma points at once
    and ``cross_variance`` is one matrix product; predict is filterpy's own, the update is
    :meth:`WindEstimator._ukf_update` (restricted force-scale gain).
    """

    proc_args: tuple = ()

    def compute_process_sigmas(self, dt, fx=None, **fx_args):  # noqa: ARG002 - filterpy signature
        sigmas = self.points_fn.sigma_points(self.x, self.P)
        _process_batch(sigmas, self.sigmas_f, dt, *self.proc_args)

    def cross_variance(self, x, z, sigmas_f, sigmas_h):
        return ((sigmas_f - x).T * self.Wc) @ (sigmas_h - z)


class WindEstimator:
    """Wind UKF with asynchronous inputs. Feed samples in time order; read :meth:`estimate`.

    Args:
        params: vehicle parameters the force model uses (exact or ``perturbed``).
        config: tuning, see :class:`EstimatorConfig`.

    Usage::

        est = WindEstimator(load_vehicle())
        est.set_attitude(t, q)            # body->NED quaternion [w, x, y, z]
        est.set_rotor_speeds(t, omega)    # rad/s (ESC telemetry or rpm_free model)
        est.imu(t, accel_frd, gyro_frd)   # predict to t, update with the specific force
        est.gnss_velocity(t_valid, v_ned) # update with a (delayed) NED velocity
        e = est.estimate()                # WindEstimate
    """

    def __init__(self, params: VehicleParams, config: EstimatorConfig | None = None) -> None:
        self.config = cfg = config or EstimatorConfig()
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
        points = MerweScaledSigmaPoints(self.n, alpha=cfg.alpha, beta=cfg.beta, kappa=cfg.kappa)
        self.ukf = _UKF(dim_x=self.n, dim_z=3, dt=0.004, hx=None, fx=None, points=points)
        self.ukf.x = np.array(x0)
        self.ukf.P = np.diag(P0)
        self._q_density = np.array(q)
        self._R_accel = np.diag(np.square(cfg.accel_noise_m_s2))
        self._R_gnss = np.diag(np.square(cfg.gnss_vel_noise_m_s))
        self.t: float | None = None  # filter time, s
        self._t_first: float | None = None  # time of the first prediction, s
        self.scale_released = not cfg.scale_state
        self._nu_ema = np.zeros(3)
        self._fz_ref = -float(self._p[P_G])  # low-passed measured body-z specific force, m/s^2
        self._fz_seen = False
        self._ema_alpha = 1.0
        self._transient_left = 0.0  # s
        self._wind_q_gain = 1.0  # wind process-noise multiplier (> 1 while a transient is detected)
        self._nu_slow = np.zeros(3)
        self._firing_s = 0.0  # how long the transient detector has been firing without a break, s
        self._dt_last = 0.0
        self.transients = 0  # times the transient detector fired
        self._R: np.ndarray | None = None  # attitude DCM body->NED
        self._q_att: np.ndarray | None = None
        self._rates = np.zeros(3)
        self._w_rot: np.ndarray | None = None
        self._last_in: dict[str, float] = {}
        self._fresh_sigmas = True  # sigmas_f reflect the current (x, P)
        self._hist: deque[tuple[float, np.ndarray]] = deque()
        self.rejected: Counter[str] = Counter()
        self.accepted: Counter[str] = Counter()
        self.direction = DirectionFilter(cfg.direction_cutoff_hz, cfg.direction_rate_hz, cfg.direction_order)
        self._dir_filtered = float("nan")

    # ------------------------------------------------------------------ input checks
    def _reject(self, reason: str) -> bool:
        self.rejected[reason] += 1
        return False

    def _check_time(self, stream: str, t: float) -> bool:
        if not math.isfinite(t):
            return self._reject(f"{stream}:bad_time")
        last = self._last_in.get(stream)
        if last is not None and t <= last:
            return self._reject(f"{stream}:duplicate_or_out_of_order")
        return True

    @staticmethod
    def _finite(a: np.ndarray, shape: int) -> bool:
        return a.shape == (shape,) and bool(np.all(np.isfinite(a)))

    # ------------------------------------------------------------------ inputs
    def set_attitude(self, t: float, q_wxyz: np.ndarray) -> bool:
        """Attitude quaternion [w, x, y, z], body FRD -> NED (from the AHRS/EKF). Held until the next."""
        q = np.asarray(q_wxyz, dtype=float)
        if not self._check_time("attitude", t):
            return False
        if not self._finite(q, 4) or abs(np.linalg.norm(q) - 1.0) > QUAT_NORM_TOL:
            return self._reject("attitude:bad_value")
        self._last_in["attitude"] = t
        q = q / np.linalg.norm(q)
        self._q_att = q
        self._R = quat_to_dcm(q)
        self.accepted["attitude"] += 1
        return True

    def set_rates(self, t: float, rates_frd: np.ndarray) -> bool:
        """Body rates (FRD, rad/s) when they come separately from the IMU (e.g. MAVLink ATTITUDE)."""
        w = np.asarray(rates_frd, dtype=float)
        if not self._check_time("rates", t):
            return False
        if not self._finite(w, 3) or np.any(np.abs(w) > GYRO_LIMIT_RAD_S):
            return self._reject("rates:bad_value")
        self._last_in["rates"] = t
        self._rates = w.copy()
        return True

    def set_rotor_speeds(self, t: float, w_rot: np.ndarray) -> bool:
        """Rotor speeds (rad/s, rotor order of ``vehicle.rotor_model``). Held until the next sample."""
        w = np.asarray(w_rot, dtype=float)
        if not self._check_time("rotors", t):
            return False
        if not self._finite(w, 4) or np.any(w < 0.0) or np.any(w > 2.0 * self._p[P_WMAX]):
            return self._reject("rotors:bad_value")
        self._last_in["rotors"] = t
        self._w_rot = w.copy()
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

    def imu(self, t: float, accel_frd: np.ndarray, gyro_frd: np.ndarray | None = None) -> bool:
        """IMU sample at time t: predict to t, then update with the specific force (FRD, m/s^2).

        ``gyro_frd`` (rad/s) becomes the rates input; pass None when rates come via set_rates.
        Returns False (and counts why) when the sample was rejected; the state is untouched then.
        """
        a = np.asarray(accel_frd, dtype=float)
        if not self._check_time("imu", t):
            return False
        if not self._finite(a, 3) or np.any(np.abs(a) > ACCEL_LIMIT_M_S2):
            return self._reject("imu:bad_value")
        if gyro_frd is not None:
            g = np.asarray(gyro_frd, dtype=float)
            if not self._finite(g, 3) or np.any(np.abs(g) > GYRO_LIMIT_RAD_S):
                return self._reject("imu:bad_value")
        if self.t is not None and t <= self.t:
            return self._reject("imu:older_than_filter")
        if not self.ready:
            return self._reject("imu:not_ready")
        self._last_in["imu"] = t
        if gyro_frd is not None:
            self._rates = g.copy()
        self.predict_to(t)
        if self._fz_seen:
            self._fz_ref += min(1.0, self._ema_alpha * self.config.transient_tau_s / self.config.fz_ref_tau_s) * (
                a[2] - self._fz_ref
            )
        else:
            self._fz_ref, self._fz_seen = float(a[2]), True
        self._update(a, self._R_accel, "accel")
        self.accepted["imu"] += 1
        self._record_history()
        return True

    def gnss_velocity(self, t_valid: float, vel_ned: np.ndarray) -> bool:
        """NED ground velocity (m/s) valid at ``t_valid`` (s; may lie up to gnss_history_s in the past).

        ``vel_ned`` has 3 components, or 2 (north, east) for receivers without a vertical
        velocity (MAVLink GPS_RAW_INT): then only the horizontal components update.
        """
        v = np.asarray(vel_ned, dtype=float)
        if not self._check_time("gnss", t_valid):
            return False
        nz = v.shape[0] if v.ndim == 1 else 0
        if nz not in (2, 3) or not self._finite(v, nz) or np.linalg.norm(v) > VELOCITY_LIMIT_M_S:
            return self._reject("gnss:bad_value")
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
            shift = self._R @ self.ukf.x[0:3] - past
        self._last_in["gnss"] = t_valid
        self._update(v + shift[:nz], self._R_gnss[:nz, :nz], "gnss")
        self.accepted["gnss"] += 1
        return True

    # ------------------------------------------------------------------ filter core
    def predict_to(self, t: float) -> None:
        """Predict the state to time t (s) with the held inputs; covariance grows over gaps."""
        if self.t is None:
            self.t = self._t_first = t
            return
        if not self.scale_released:
            self._maybe_release_scale(t)
        span = t - self.t
        if span > 0.0:
            self._transient_left -= span
            self._dt_last = span
            self._ema_alpha = min(1.0, span / self.config.transient_tau_s)
        span = min(t - self.t, self.config.max_gap_s)
        if span > 0.0 and self.ready:
            n = max(1, math.ceil(span / self.config.max_step_s - 1e-9))
            dt = span / n
            tau = self.config.vertical_wind_tau_s
            decay = math.exp(-dt / tau) if tau else 1.0
            self.ukf.proc_args = (self._R, self._rates, self._w_rot, self._p, decay, self._i_scale, self._fz_ref)
            q = self._q_density
            if self._wind_q_gain != 1.0:
                q = q.copy()
                q[3:6] *= self._wind_q_gain
            for _ in range(n):
                self.ukf.Q = np.diag(q * dt)
                self._guarded(lambda: self.ukf.predict(dt=dt))
            self._fresh_sigmas = True
        self.t = max(self.t, t)

    def _maybe_release_scale(self, t: float) -> None:
        cfg = self.config
        held = t - self._t_first
        if held < cfg.scale_hold_s:
            return
        # The horizontal wind converges whatever the model error (the vertical may not: the
        # scale is what fixes it); release anyway after three hold times.
        if np.max(np.diag(self.ukf.P)[3:5]) > cfg.scale_release_wind_sigma_m_s**2 and held < 3.0 * cfg.scale_hold_s:
            return
        i = self._i_scale
        self.ukf.P[i, :] = 0.0
        self.ukf.P[:, i] = 0.0
        self.ukf.P[i, i] = cfg.scale_sigma0**2
        self._q_density[i] = cfg.scale_walk_per_sqrt_s**2
        self.scale_released = True

    def _update(self, z: np.ndarray, R: np.ndarray, kind: str) -> None:
        ukf = self.ukf
        if not self._fresh_sigmas:
            # filterpy's update reuses the sigma points drawn after predict; a second update
            # in the same step needs points drawn from the updated (x, P).
            ukf.sigmas_f = ukf.points_fn.sigma_points(ukf.x, ukf.P)
        if kind == "accel":
            h = _accel_batch(
                ukf.sigmas_f, self._R, self._rates, self._w_rot, self._p, self._i_scale, self._bias_idx, self._fz_ref
            )
        else:
            Rm = self._R
            h = (ukf.sigmas_f[:, 0:3] @ Rm.T)[:, : len(z)]
        self._guarded(lambda: self._ukf_update(z, R, h, kind))
        self._fresh_sigmas = False

    def _ukf_update(self, z: np.ndarray, R: np.ndarray, h: np.ndarray, kind: str) -> None:
        """Unscented update with measurement sigma points ``h``; the force scale only learns
        from the body-z accelerometer innovation, and not during a transient.

        The scale's gain row is restricted (a suboptimal gain), so the covariance is updated
        in the general form P - K Pxz^T - Pxz K^T + K S K^T, valid for any gain.
        """
        ukf = self.ukf
        Wm, Wc = ukf.Wm, ukf.Wc
        zp = Wm @ h
        dz = h - zp
        S = (dz.T * Wc) @ dz + R
        Pxz = ((ukf.sigmas_f - ukf.x).T * Wc) @ dz
        K = np.linalg.solve(S, Pxz.T).T
        y = z - zp
        i = self._i_scale
        if kind == "accel":
            self._watch_innovation(y, S)
        if i >= 0:
            K[i, :] = 0.0
            if kind == "accel" and self.scale_released and self._transient_left <= 0.0:
                K[i, 2] = Pxz[i, 2] / S[2, 2]
            KP = K @ Pxz.T
            ukf.P = ukf.P - KP - KP.T + K @ S @ K.T
        else:
            ukf.P = ukf.P - K @ S @ K.T
        ukf.x = ukf.x + K @ y

    def _watch_innovation(self, y: np.ndarray, S: np.ndarray) -> None:
        """Transient detector: a low-passed normalized horizontal accelerometer innovation far
        from zero means the wind is changing faster than its random walk. While it lasts the wind
        process noise is raised (``transient_wind_q_gain``), and for ``transient_hold_s`` after
        it the force scale is frozen (a wind step must not be explained by a mass change)."""
        cfg = self.config
        a = self._ema_alpha
        nu = y / np.sqrt(np.diag(S))
        self._nu_ema = (1.0 - a) * self._nu_ema + a * nu
        b = min(1.0, self._dt_last / cfg.transient_baseline_tau_s)
        self._nu_slow = (1.0 - b) * self._nu_slow + b * nu
        # Horizontal axes only, against the slow baseline: a persistent innovation (z, or a
        # steady bias on x and y) is what a force-model error looks like and the scale must
        # learn from it; a wind step is a fast change on x and y.
        d = self._nu_ema - self._nu_slow
        if max(abs(d[0]), abs(d[1])) > cfg.transient_threshold:
            if self._firing_s == 0.0:
                self.transients += 1
            self._firing_s += self._dt_last
            if self._firing_s <= cfg.transient_max_s:
                self._transient_left = cfg.transient_hold_s
                self._wind_q_gain = cfg.transient_wind_q_gain
            else:
                # Innovations that stay biased are model error, not a wind step: the scale
                # must learn from them, so neither freeze it nor keep the wind noise raised.
                self._transient_left = 0.0
                self._wind_q_gain = 1.0
        else:
            self._firing_s = 0.0
            self._wind_q_gain = 1.0

    def _guarded(self, op) -> None:
        """Run a filter operation; on a numerical failure restore the state and count it."""
        x, P = self.ukf.x.copy(), self.ukf.P.copy()
        try:
            op()
            P = self.ukf.P
            self.ukf.P = 0.5 * (P + P.T)
            if not (np.all(np.isfinite(self.ukf.x)) and np.all(np.isfinite(self.ukf.P))):
                raise np.linalg.LinAlgError("non-finite state")
        except np.linalg.LinAlgError:
            self.ukf.x, self.ukf.P = x, P + 1e-6 * np.eye(self.n)
            self.rejected["numerical"] += 1

    def _record_history(self) -> None:
        v_ned = self._R @ self.ukf.x[0:3]
        self._hist.append((self.t, v_ned))
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
                t0, v0 = prev
                t1, v1 = item
                if t1 <= t0:
                    return v1
                a = (t - t0) / (t1 - t0)
                return v0 + a * (v1 - v0)
            prev = item
        return h[-1][1]

    # ------------------------------------------------------------------ outputs
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
