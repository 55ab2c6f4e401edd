"""Measured conditions for the STE likelihood: how far the wind direction wanders.

The detection model of ``mission.strategies.ste_model`` was fitted to one plume (moderate
turbulence, a steady mean wind): a 6.2 deg meander, an intermittency length, and a tempering of
the readings (0.8). Where the wind direction wanders further -- high turbulence, a wind
that turns in steps -- the plume swings wider and more often away than that model says, its
misses on the true source's plume are a model error, and the posterior becomes sure of wrong
places (issue 19: a 90 % region that held the source in 75-80 % of declarations).

What the vehicle can measure is the spread of its own wind estimate's direction: the circular
standard deviation ``sqrt(-2 ln R)`` of the horizontal wind's unit vector over the last
``tau_s`` (an exponentially weighted mean resultant length ``R``, bias-corrected at the start).
Measured with the UKF's estimate over 20 s windows (development seeds 100-102): 6.5-8.2 deg
(median) in open-field and open-field-far, 12.6-15.6 deg in open-field-high, 17.8-20.9 deg in
paper-anemotaxis (45 deg steps every 10 s). Above a reference spread the likelihood is widened
by the ratio ``f = spread / reference`` (:func:`mismatch_factor`): the meander's direction sigma
times ``f ** meander_power`` and the tempering exponent divided by ``f ** tempering_power``
(``Infotaxis`` applies both before each posterior update). Below the reference nothing changes:
the model stays the one fitted where it holds. **On above 12 deg by default**
(``spread_reference_deg``; 0 turns it off). Development seeds 200-259, within 3 m / 90 % region
held: paper-anemotaxis 82 / 75 % without it, 98 / 95 % with it; open-field-high 83 / 92 % without,
73 / 91 % with (honest both ways, slower with it: more timeouts); ``mission/README.md``, Infotaxis.

Units: s, rad; the wind is the air-mass velocity (north, east) [m/s].
"""

from __future__ import annotations

import math


class DirectionSpread:
    """Exponentially weighted circular spread of the wind direction estimate.

    ``add`` takes the horizontal wind (north, east) [m/s] and the time since the last sample [s];
    ``spread_rad`` is ``sqrt(-2 ln R)`` [rad] of the weighted mean unit vector, 0 before any
    sample (or for a wind too weak to have a direction, which is skipped)."""

    def __init__(self, tau_s: float, min_speed_m_s: float = 0.5) -> None:
        if tau_s <= 0.0:
            raise ValueError(f"tau_s = {tau_s}: must be > 0")
        self.tau_s = float(tau_s)
        self.min_speed = float(min_speed_m_s)
        self._c = 0.0
        self._s = 0.0
        self._mass = 0.0  # total weight so far, 1 - exp(-t / tau): the mean is (c, s) / mass

    def add(self, wind_n: float, wind_e: float, dt: float) -> None:
        """One wind sample [m/s, NED horizontal]; ``dt`` [s] since the previous one."""
        sp = math.hypot(wind_n, wind_e)
        if not (sp >= self.min_speed) or not math.isfinite(sp):
            return
        a = -math.expm1(-max(dt, 1e-3) / self.tau_s)
        self._c += a * (wind_n / sp - self._c)
        self._s += a * (wind_e / sp - self._s)
        self._mass += a * (1.0 - self._mass)

    @property
    def spread_rad(self) -> float:
        """Circular standard deviation [rad] of the direction over the last ``tau_s``."""
        if self._mass <= 0.0:
            return 0.0
        r = math.hypot(self._c, self._s) / self._mass
        return math.sqrt(-2.0 * math.log(min(max(r, 1e-12), 1.0)))


def mismatch_factor(spread_rad: float, reference_rad: float) -> float:
    """``f`` = measured direction spread over the spread the model holds to, at least 1."""
    if reference_rad <= 0.0 or not math.isfinite(spread_rad):
        return 1.0
    return max(1.0, spread_rad / reference_rad)


def adapted_likelihood(f: float, tempering: float, meander_rad: float, tempering_power: float,
                       meander_power: float) -> tuple[float, float]:
    """(tempering exponent, meander direction sigma [rad]) for the mismatch factor ``f`` >= 1."""
    return tempering / f**tempering_power, meander_rad * f**meander_power
