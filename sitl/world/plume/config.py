"""Plume configuration: sources, stability class, model and limits, validated.

SI units except the chemical quantities (release in g/s, concentration in mg/m^3); NED world
frame (the ground is z = 0); stability as a Pasquill-Gifford class "A" (very unstable) .. "F".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

STABILITY_CLASSES: tuple[str, ...] = ("A", "B", "C", "D", "E", "F")
PLUME_MODELS: tuple[str, ...] = ("puff", "gaussian")

G_TO_MG = 1000.0
TWO_PI_POW_1_5 = (2.0 * math.pi) ** 1.5


class WindLike(Protocol):
    """What the plume needs from a wind model (e.g. ``sitl.world.wind.WindField``)."""

    def mean(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Steady air-mass velocity NED [m/s] at ``pos_ned`` (3,), no turbulence."""
        ...

    def velocity(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Air-mass velocity NED [m/s] with turbulence; (N,3) -> (N,3)."""
        ...


@dataclass(frozen=True)
class Source:
    """A point release.

    position_ned: release point, NED [m] (altitude = -z, must be >= 0).
    rate_g_s: release rate [g/s].
    start_s / stop_s: the source emits for start_s <= t < stop_s [s].
    """

    position_ned: tuple[float, float, float]
    rate_g_s: float
    start_s: float = 0.0
    stop_s: float = math.inf

    def active(self, t: float) -> bool:
        """True while the source emits at time ``t`` [s]."""
        return self.start_s <= t < self.stop_s


@dataclass(frozen=True)
class PlumeConfig:
    """Plume configuration.

    sources: the releases (at least one).
    stability: Pasquill-Gifford class, one of STABILITY_CLASSES.
    model: "puff" (instantaneous, Farrell) or "gaussian" (time-averaged).
    puff_rate_hz: puffs released per second per source.
    max_puffs: cap on live puffs; the oldest are removed (mass accounted).
    update_rate_hz: the puff model integrates with steps no longer than 1/update_rate_hz;
        the simulator should call ``step`` at this rate.
    domain_min_ned / domain_max_ned: optional box [m, NED]; puffs leaving it are removed.
        Either both or neither.
    source_radius_m: initial puff standard deviation r0 [m] (also the virtual source
        size of the Gaussian plume).
    min_wind_speed_m_s: floor on the wind speed used for dilution and dispersion
        scaling, so calm air does not give infinite concentration.
    subtract_wind_turbulence: take the variance of the wind model's Taylor-frozen
        turbulence out of the meander budget so the total spread stays that of the
        stability class (puff model only).
    """

    sources: tuple[Source, ...]
    stability: str = "D"
    model: str = "puff"
    puff_rate_hz: float = 10.0
    max_puffs: int = 1000
    update_rate_hz: float = 10.0
    domain_min_ned: tuple[float, float, float] | None = None
    domain_max_ned: tuple[float, float, float] | None = None
    source_radius_m: float = 0.3
    min_wind_speed_m_s: float = 0.5
    subtract_wind_turbulence: bool = True

    def validate(self) -> list[str]:
        """Return a list of human-readable errors (empty when valid)."""
        errors: list[str] = []
        if len(self.sources) == 0:
            errors.append("sources: at least one Source is required")
        for i, s in enumerate(self.sources):
            pos = np.asarray(s.position_ned, dtype=float)
            if pos.shape != (3,) or not np.all(np.isfinite(pos)):
                errors.append(f"sources[{i}].position_ned: 3 finite NED coordinates [m]")
            elif pos[2] > 0.0:
                errors.append(f"sources[{i}].position_ned: z must be <= 0 (above ground, NED)")
            if not (math.isfinite(s.rate_g_s) and s.rate_g_s >= 0.0):
                errors.append(f"sources[{i}].rate_g_s: finite and >= 0 [g/s]")
            if not (math.isfinite(s.start_s) and s.stop_s > s.start_s):
                errors.append(f"sources[{i}].start_s/stop_s: finite start_s < stop_s [s]")
        if self.stability not in STABILITY_CLASSES:
            errors.append(f"stability: one of {', '.join(STABILITY_CLASSES)}")
        if self.model not in PLUME_MODELS:
            errors.append(f"model: one of {', '.join(PLUME_MODELS)}")
        if not (math.isfinite(self.puff_rate_hz) and self.puff_rate_hz > 0.0):
            errors.append("puff_rate_hz: finite and > 0 [Hz]")
        if self.max_puffs < 1:
            errors.append("max_puffs: integer >= 1")
        if not (math.isfinite(self.update_rate_hz) and self.update_rate_hz > 0.0):
            errors.append("update_rate_hz: finite and > 0 [Hz]")
        if (self.domain_min_ned is None) != (self.domain_max_ned is None):
            errors.append("domain_min_ned/domain_max_ned: give both or neither")
        elif self.domain_min_ned is not None and self.domain_max_ned is not None:
            lo = np.asarray(self.domain_min_ned, dtype=float)
            hi = np.asarray(self.domain_max_ned, dtype=float)
            if lo.shape != (3,) or hi.shape != (3,) or not np.all(lo < hi):
                errors.append("domain_min_ned/domain_max_ned: 3 values each, min < max per axis")
        if not (math.isfinite(self.source_radius_m) and self.source_radius_m > 0.0):
            errors.append("source_radius_m: finite and > 0 [m]")
        if not (math.isfinite(self.min_wind_speed_m_s) and self.min_wind_speed_m_s > 0.0):
            errors.append("min_wind_speed_m_s: finite and > 0 [m/s]")
        return errors


def check_config(config: PlumeConfig) -> None:
    """ValueError listing every problem of ``config``."""
    errors = config.validate()
    if errors:
        raise ValueError("invalid PlumeConfig: " + "; ".join(errors))
