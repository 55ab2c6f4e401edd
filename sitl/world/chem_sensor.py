"""Chemical (gas concentration) sensor model for the vehicle.

Conventions: SI units (s, Hz); concentration in mg/m^3, the unit of ``sitl.world.plume``.
The sensor is a point sensor at the vehicle position (NED, see ``sitl.world.plume``); the
caller evaluates the true concentration there and passes it in.

Model, per reading at time t:

1. First-order response (time constant tau) of the sensing element, discretised
   exactly for a zero-order-held input: over an interval dt the state moves toward the
   input by the fraction 1 - exp(-dt / tau). The input held is the concentration given
   with the reading (the most recent one the caller knows). The element starts in clean
   air (state 0) unless ``initial_mg_m3`` says otherwise.
2. Additive white Gaussian noise of standard deviation ``noise_std_mg_m3``, independent
   per reading (seeded ``np.random.Generator``: same seed, same readings).
3. Saturation: the reading is clipped to [0, saturation_mg_m3] (a concentration
   cannot be negative; the electronics rail at the top) and flagged ``saturated``.
4. Detection limit: readings below ``detection_limit_mg_m3`` are reported as 0.0 and
   flagged ``detected = False``; callers should treat them as "below limit", not as
   clean air.

Defaults are PID-like (a miniature photo-ionisation detector on a small multirotor):
tau = 0.5 s (t90 = 2.3 tau ~ 1.2 s), noise 0.01 mg/m^3, detection limit 0.05 mg/m^3
(5 sigma of the noise, so false detections in clean air are ~3e-7 per reading),
saturation 1000 mg/m^3, 10 Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ChemSensorConfig:
    """Sensor parameters (see module docstring for the model).

    time_constant_s: first-order response time constant tau [s] (> 0).
    noise_std_mg_m3: white noise standard deviation per reading [mg/m^3] (>= 0).
    detection_limit_mg_m3: readings below this are reported as 0, not detected [mg/m^3] (>= 0).
    saturation_mg_m3: full scale; readings are clipped to it [mg/m^3] (> detection limit).
    sample_rate_hz: rate at which the simulator should call ``sample`` [Hz] (> 0).
    initial_mg_m3: state of the sensing element at the first reading [mg/m^3] (>= 0).
    """

    time_constant_s: float = 0.5
    noise_std_mg_m3: float = 0.01
    detection_limit_mg_m3: float = 0.05
    saturation_mg_m3: float = 1000.0
    sample_rate_hz: float = 10.0
    initial_mg_m3: float = 0.0

    def validate(self) -> list[str]:
        """Return a list of human-readable errors (empty when valid)."""
        errors: list[str] = []

        def check(name: str, ok: bool, allowed: str) -> None:
            if not (math.isfinite(getattr(self, name)) and ok):
                errors.append(f"{name}: {allowed}, got {getattr(self, name)!r}")

        check("time_constant_s", self.time_constant_s > 0.0, "finite and > 0 [s]")
        check("noise_std_mg_m3", self.noise_std_mg_m3 >= 0.0, "finite and >= 0 [mg/m^3]")
        check(
            "detection_limit_mg_m3", self.detection_limit_mg_m3 >= 0.0, "finite and >= 0 [mg/m^3]"
        )
        check(
            "saturation_mg_m3",
            self.saturation_mg_m3 > self.detection_limit_mg_m3,
            "finite and > detection_limit_mg_m3 [mg/m^3]",
        )
        check("sample_rate_hz", self.sample_rate_hz > 0.0, "finite and > 0 [Hz]")
        check("initial_mg_m3", self.initial_mg_m3 >= 0.0, "finite and >= 0 [mg/m^3]")
        return errors

    @property
    def period_s(self) -> float:
        """Sample period [s]."""
        return 1.0 / self.sample_rate_hz


@dataclass(frozen=True)
class ChemReading:
    """One sensor reading.

    t: time of the reading [s].
    value_mg_m3: reported concentration [mg/m^3]; 0.0 when not detected.
    detected: the reading is at or above the detection limit.
    saturated: the reading was clipped at full scale.
    """

    t: float
    value_mg_m3: float
    detected: bool
    saturated: bool


class ChemicalSensor:
    """Seeded first-order chemical sensor with noise, detection limit and saturation."""

    def __init__(self, config: ChemSensorConfig, seed: int | np.random.SeedSequence):
        """config: sensor parameters (ValueError lists the problems); seed: int or
        SeedSequence for the noise."""
        errors = config.validate()
        if errors:
            raise ValueError("invalid ChemSensorConfig: " + "; ".join(errors))
        self.config = config
        self._rng = np.random.default_rng(seed)
        self._state = float(config.initial_mg_m3)
        self._t_last: float | None = None

    @property
    def state_mg_m3(self) -> float:
        """Noise-free filtered concentration of the sensing element [mg/m^3]."""
        return self._state

    def sample(self, t: float, true_concentration_mg_m3: float) -> ChemReading:
        """Reading at time ``t`` [s] given the true concentration [mg/m^3] at the sensor.

        Call at ``config.sample_rate_hz``; the filter is exact for any spacing of calls.
        Times must not decrease (ValueError otherwise).
        """
        cfg = self.config
        c = max(float(true_concentration_mg_m3), 0.0)
        if self._t_last is not None:
            dt = t - self._t_last
            if dt < 0.0:
                raise ValueError(f"t must not decrease: {t} s after {self._t_last} s")
            alpha = -math.expm1(-dt / cfg.time_constant_s)
            self._state += alpha * (c - self._state)
        self._t_last = t
        raw = self._state + cfg.noise_std_mg_m3 * float(self._rng.standard_normal())
        saturated = raw >= cfg.saturation_mg_m3
        value = min(max(raw, 0.0), cfg.saturation_mg_m3)
        detected = value >= cfg.detection_limit_mg_m3
        return ChemReading(
            t=t, value_mg_m3=value if detected else 0.0, detected=detected, saturated=saturated
        )
