"""Tuning of the wind UKF: :class:`EstimatorConfig` and its two presets (``calibrated``, ``uncalibrated``).

Noise values are 1-sigma in SI (m/s, m/s^2); random-walk densities are per sqrt(s). Why each value is
what it is, and which seeds it was chosen on, is in the field comments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any


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
    #: The IMU rate ``accel_noise_m_s2`` is stated for [Hz]; at another rate the per-sample variance
    #: scales with the rate (WindEstimator._accel_rate_factor: a constant noise density).
    accel_noise_rate_hz: float = 250.0
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
    #: Transient detector (see estimator.step_kernels.watch_innovation): time constant (s) of the
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
    #: 1-sigma of the horizontal accelerometer bias no state carries (m/s^2, per body axis), added to
    #: the reported wind covariance through the force model (WindEstimator.unseen_bias_cov). At a
    #: constant heading it is the same force as a wind change, so no filter can estimate it, and
    #: the estimate is off by it for the whole flight: the dominant error of a steady hover (issue
    #: 29). 0.02 is the turn-on bias of a MEMS accelerometer after calibration (a datasheet value;
    #: windseek's IMU draws it per flight). Without it the stated 95 % circle held the error in
    #: 78-100 % of each flight on the development seeds (100-111, open-field, 90 s), with it 92-100 %.
    unseen_accel_bias_m_s2: float = 0.02
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
    def uncalibrated(cls, **overrides: Any) -> EstimatorConfig:
        """Vehicle not identified (mass and force model known to a few %): force-scale state,
        mean-reverting vertical wind. The default, and the right choice for a real vehicle
        unless it was identified."""
        return replace(cls(), **overrides)

    @classmethod
    def calibrated(cls, **overrides: Any) -> EstimatorConfig:
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
    def for_vehicle(cls, vehicle: Any, **overrides: Any) -> EstimatorConfig:
        """The preset a vehicle file calls for (:func:`preset_for`). When the file records the accelerometer
        noise its identification flight measured (``[model.info] accel_noise_m_s2``, 1-sigma per sample, FRD:
        ``windseek identify --connect``; PX4 SIH's is 0.3-1.2 m/s^2, ten times windseek's IMU), the
        accelerometer noise is the preset's and the measured one added in quadrature."""
        noise = (getattr(vehicle, "model_info", {}) or {}).get("accel_noise_m_s2")
        if noise is not None and "accel_noise_m_s2" not in overrides and len(noise) == 3:
            base = cls.preset(preset_for(vehicle)).accel_noise_m_s2
            overrides["accel_noise_m_s2"] = tuple(math.hypot(a, float(b)) for a, b in zip(base, noise, strict=True))
        return cls.preset(preset_for(vehicle), **overrides)

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> EstimatorConfig:
        """The preset called ``name`` (one of :data:`PRESETS`)."""
        if name not in PRESETS:
            raise ValueError(f"unknown estimator calibration {name!r}; choose from {', '.join(PRESETS)}")
        return getattr(cls, name)(**overrides)


#: Preset names of :meth:`EstimatorConfig.preset`: whether the vehicle's mass and force model
#: were identified. Real vehicles default to ``uncalibrated``.
PRESETS = ("calibrated", "uncalibrated")


def preset_for(vehicle: Any) -> str:
    """``calibrated`` when the vehicle file's model was identified for it (``windseek identify`` wrote its fit
    into ``[model.info]``), ``uncalibrated`` otherwise."""
    info = getattr(vehicle, "model_info", {}) or {}
    identified = "fit" in info and str(info.get("source", "")).startswith("windseek identify")
    return "calibrated" if identified else "uncalibrated"
