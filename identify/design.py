"""The identification manoeuvre (paper, System Identification Results): what is flown, as signals.

The paper's manoeuvre is 5 s of hover, then 2 min of a 4-axis orthogonal phase-optimized multisine on
the virtual actuators (delta_t, delta_a, delta_e, delta_r: Eq. 40), turned into motor commands through
the pseudo-inverse of the mixing matrix M_ix so the four inputs stay orthogonal at the motors, plus a
low-frequency reference (0.001-0.01 Hz) that moves the vehicle through a range of operating
conditions. An independent validation manoeuvre uses a different multisine and reference.

Here the low-frequency reference is flown as a velocity (north, east, down) and heading reference
whose attitude is the paper's slow attitude reference (a multirotor tilts to accelerate), with two
differences said plainly: its band starts at the manoeuvre's first harmonic (1 / 120 s: 0.0083 Hz;
a 2 min manoeuvre holds no slower cycle), and it is a velocity, so the excursion stays bounded (a
geofence can hold it) while the airspeeds cover the domain the estimator will meet (default peaks
8 m/s horizontally, 2 m/s vertically: the scenarios' winds reach 10 m/s and 3 m/s updrafts). The heading sweeps so the
airspeed visits every body axis.

Units: virtual actuators in rad^2/s^2 (squared rotor speeds, as Eq. 40); the defaults scale them by
the hover value of delta_t = N w_hover^2. Velocities NED m/s, heading rad, times s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from identify.multisine import Multisine, design_multisine

#: Sample period of the designed multisines, s (33 samples per period at 3 Hz; the excitation is evaluated
#: at every physics tick from the same sum of sines).
DESIGN_DT_S = 0.01


@dataclass(frozen=True)
class ManoeuvreSpec:
    """Options of one manoeuvre (fitting or validation). Amplitudes of the motor multisine are the
    peak of each virtual actuator as a fraction of the hover ``delta_t`` (thrust, roll, pitch, yaw)."""

    hover_s: float = 5.0
    duration_s: float = 120.0
    band_hz: tuple[float, float] = (0.2, 3.0)
    # The largest with no motor at its limit in the fitting flights of the built-in vehicles (a quarter of the
    # rotor-speed range about hover): the larger the excitation, the larger the moments against the gyro's and
    # the turbulence's noise (0.035 on roll and pitch left their R^2 at 97 %).
    amplitudes: tuple[float, float, float, float] = (0.15, 0.08, 0.08, 0.15)
    reference_band_hz: tuple[float, float] = (1.0 / 120.0, 0.04)
    speed_m_s: float = 8.0  # peak of each horizontal velocity reference
    climb_m_s: float = 2.0  # peak of the vertical velocity reference
    heading_rad: float = math.pi  # peak of the heading reference about the start heading
    seed: int = 0

    def validate(self) -> None:
        """ValueError naming the option."""
        checks = [("hover_s", self.hover_s, 0.0, 600.0), ("duration_s", self.duration_s, 10.0, 3600.0),
                  ("speed_m_s", self.speed_m_s, 0.0, 20.0), ("climb_m_s", self.climb_m_s, 0.0, 4.0),
                  ("heading_rad", self.heading_rad, 0.0, 2 * math.pi)]  # fmt: skip
        checks += [(f"amplitudes[{i}]", a, 0.0, 0.5) for i, a in enumerate(self.amplitudes)]
        for name, v, lo, hi in checks:
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"manoeuvre {name} = {v!r}: allowed range is [{lo}, {hi}]")
        for name, (f0, f1) in (("band_hz", self.band_hz), ("reference_band_hz", self.reference_band_hz)):
            if not (0.0 < f0 < f1 and math.isfinite(f1)):
                raise ValueError(f"manoeuvre {name} = {(f0, f1)!r}: needs 0 < low < high")
        if self.band_hz[0] * self.duration_s < 4.0 or self.band_hz[1] > 0.25 / DESIGN_DT_S:
            raise ValueError(f"manoeuvre band_hz = {self.band_hz!r}: needs low >= 4 / duration_s and high <= "
                             f"{0.25 / DESIGN_DT_S:g} Hz")  # fmt: skip


@dataclass(frozen=True)
class ExperimentSpec:
    """The fitting manoeuvre and the validation manoeuvre (a different multisine, a different reference)."""

    fitting: ManoeuvreSpec = field(default_factory=ManoeuvreSpec)
    validation: ManoeuvreSpec = field(default_factory=lambda: ManoeuvreSpec(duration_s=60.0, seed=1))


@dataclass(frozen=True, eq=False)
class Manoeuvre:
    """A designed manoeuvre: the motor multisine (4 virtual actuators, rad^2/s^2 peaks already applied) and
    the reference (north, east, down velocity m/s and heading offset rad), both starting after the hover."""

    spec: ManoeuvreSpec
    virtual: Multisine
    reference: Multisine
    scale: np.ndarray  # (4,) rad^2/s^2 per unit of the virtual multisine (its amplitudes are fractions)

    def virtual_at(self, t: np.ndarray) -> np.ndarray:
        """Virtual actuator excitation (n, 4), rad^2/s^2, at manoeuvre times ``t`` (s from the start,
        zero during the hover and after the end)."""
        t = np.asarray(t, dtype=float)
        u = self.virtual.at(np.clip(t - self.spec.hover_s, 0.0, self.spec.duration_s)) * self.scale
        active = (t >= self.spec.hover_s) & (t <= self.spec.hover_s + self.spec.duration_s)
        return np.where(active[:, None], u, 0.0)

    def reference_at(self, t: float) -> tuple[np.ndarray, float]:
        """(velocity NED m/s, heading offset rad) at manoeuvre time ``t`` s: zero in the hover."""
        tau = t - self.spec.hover_s
        if tau <= 0.0 or tau >= self.spec.duration_s:
            return np.zeros(3), 0.0
        r = self.reference.at(np.array([tau]))[0]
        return r[:3].copy(), float(r[3])

    def position_reference(self, t: float) -> np.ndarray:
        """The integral of the velocity reference from the start (NED m): the position the velocity
        reference alone would reach (so a position loop can hold the path without drifting)."""
        tau = min(max(t - self.spec.hover_s, 0.0), self.spec.duration_s)
        out = np.zeros(3)
        for j in range(3):
            f, a, ph = (self.reference.frequencies_hz[j], self.reference.component_amplitudes[j],
                        self.reference.phases_rad[j])  # fmt: skip
            w = 2.0 * math.pi * np.asarray(f)
            out[j] = float(np.sum(np.asarray(a) * (np.sin(w * tau + ph) - np.sin(ph)) / w))
        return out

    @property
    def total_s(self) -> float:
        return self.spec.hover_s + self.spec.duration_s


def design(spec: ManoeuvreSpec, hover_delta_t: float) -> Manoeuvre:
    """Design one manoeuvre. ``hover_delta_t``: N w_hover^2 (rad^2/s^2), the amplitudes' unit."""
    spec.validate()
    virtual = design_multisine(4, spec.duration_s, DESIGN_DT_S, spec.band_hz[0], spec.band_hz[1],
                               amplitudes=[1.0, 1.0, 1.0, 1.0], seed=spec.seed)  # fmt: skip
    f0, f1 = spec.reference_band_hz
    # at least one harmonic of 1 / T per reference input (a short manoeuvre widens the band upwards)
    f0, f1 = max(f0, 1.0 / spec.duration_s), max(f1, 4.5 / spec.duration_s)
    ref = design_multisine(4, spec.duration_s, 0.05, f0, f1,
                           amplitudes=[spec.speed_m_s, spec.speed_m_s, spec.climb_m_s, spec.heading_rad],
                           seed=spec.seed + 1000)  # fmt: skip
    scale = np.asarray(spec.amplitudes, dtype=float) * hover_delta_t
    return Manoeuvre(spec=spec, virtual=virtual, reference=ref, scale=scale)


def motor_excitation(virtual: np.ndarray, mixing: np.ndarray) -> np.ndarray:
    """Squared rotor-speed perturbations (n, N) from virtual actuators (n, 4) through the pseudo-inverse
    of M_ix (Eq. 40): the orthogonality of the four inputs survives at the motors."""
    return virtual @ np.linalg.pinv(mixing).T
