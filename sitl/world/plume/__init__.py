"""The chemical plume: time-averaged Gaussian plume and instantaneous puff (filament) plume, as a world part.

Modules: ``config`` (sources, stability, limits), ``setup`` (the scenario's ``[plume]`` table),
``gaussian`` (the reference plume), ``meander`` and ``puffs`` (the instantaneous plume),
``part`` (:class:`PlumePart`: the plume and the chemical sensor in the world).

Conventions
-----------
- SI units throughout, except the two chemical quantities below.
- World frame NED: x north, y east, z down; the ground is the plane z = 0 and
  altitude = -z. All positions are NED metres.
- Wind is the AIR-MASS VELOCITY in NED (m/s): a 10 m/s wind from the north is
  [-10, 0, 0]. The plume is carried *with* that velocity.
- Release rate in g/s; puff masses in g; concentration in mg/m^3.
- Stability: Pasquill-Gifford classes "A" (very unstable) ... "F" (moderately stable).

Models
------
``gaussian_plume_concentration`` / ``GaussianPlume``
    Steady Gaussian plume with ground reflection (image source) and the Briggs
    open-country dispersion coefficients sigma_y(x), sigma_z(x). The formulas are
    tabulated for 100 m < x < 10 km; we extrapolate them to shorter range (they are
    linear in x there, which is what short-range Taylor dispersion gives). A source
    size ``source_radius_m`` is added in quadrature (virtual source) so the field is
    finite at the source. This is the reference for the puff model and a cheap
    likelihood model.

``PuffPlume``
    Instantaneous plume in the manner of Farrell et al. (2002), "Filament-based
    atmospheric dispersion model to achieve short time-scale structure of odor
    plumes" (the model implemented by pompy). Puffs are released from every active
    source at ``puff_rate_hz``; each carries ``rate_g_s / puff_rate_hz`` grams. A puff
    centre moves with

    - the wind the vehicle feels: ``wind.velocity(t, puff_positions)`` (mean, schedule,
      Kaimal turbulence of the wind model),
    - a large-scale *meander*: a smooth random velocity field (sum of random Fourier
      modes, frozen in a frame advected with the mean wind and slowly evolving in
      time) that makes the plume snake; horizontal and vertical parts (the vertical
      part gives the looping of unstable classes),
    - a small-scale random walk (puff-relative dispersion),

    and its radius grows by diffusion, r^2(t) = r0^2 + gamma * age (Farrell's model).
    Concentration is the sum of isotropic 3-D Gaussian puffs of standard deviation r,
    each with its ground image.

Calibration of the puff model against Pasquill-Gifford / Briggs
---------------------------------------------------------------
For one axis (crosswind y or vertical z) Briggs gives sigma(x) = a x (1 + b x)^p.
With travel time tau = x / u (u = reference mean wind speed at the first source,
floored at ``min_wind_speed_m_s``) the puff model spreads puffs with variance

    sigma^2(x) = MEANDER_FRACTION * a^2 u^2 * S_T(tau)          (correlated meander)
               + a^2 * DIFFUSIVE_LENGTH_M * u * tau             (random walk + puff growth)
               + r0^2                                           (source size, also in the
                                                                 Gaussian reference)

where S_T(tau) = 2 T^2 (tau/T - 1 + exp(-tau/T)) is Taylor's dispersion for velocity
fluctuations with unit variance and an exponential Lagrangian correlation time T.
T is matched to the first-order bend of the Briggs curve (T = 1/(3 b u) for
p = -1/2, T = 1/(6 b u) for p = -1, frozen when b = 0). With MEANDER_FRACTION = 0.85
and DIFFUSIVE_LENGTH_M = 3 m the design sigma is within +-8 % of Briggs for every class
and both axes over 10 m < x < 300 m, i.e. the meander velocity standard deviation is
sqrt(0.85) a u and the small-scale variance rate is 3 a^2 u m^2/s per axis. The puff
radius takes half of the smaller (of y, z) small-scale budget, the centre random walk
the rest, so the instantaneous plume (puff + random walk) is several times narrower
than the time-averaged one: patchy, meandering, intermittent. Because a, b differ by
class, class A spreads fastest (looping) and F slowest (fanning).

The meander only decorrelates through its slow temporal evolution and through
puffs drifting across the frozen field, and the field has a finite number of modes,
so the realised spread is close to, not exactly, the design; tests compare the
long-time average with the Gaussian plume within a stated tolerance.

Turbulence in the wind model (Kaimal) moves puffs too. ``sitl.world.wind`` samples it
Taylor-frozen, so a puff riding with the mean wind keeps the same turbulent velocity
for its whole life: it acts like meander with an infinite correlation time. By default
(``subtract_wind_turbulence``) its crosswind / vertical variance is removed from the
meander budget, so the total spread stays that of the stability class; when the wind
turbulence alone exceeds the class budget the plume is wider than the class.

All randomness comes from ``np.random.SeedSequence(seed)``: same seed, same field.
"""

from sitl.world.plume.config import PLUME_MODELS, STABILITY_CLASSES, PlumeConfig, Source, WindLike
from sitl.world.plume.gaussian import GaussianPlume, briggs_sigmas, gaussian_plume_concentration
from sitl.world.plume.part import CHEM_OUTPUT, PlumePart
from sitl.world.plume.puffs import PuffPlume, make_plume
from sitl.world.plume.setup import PlumeSetup, parse_plume_table

__all__ = [
    "CHEM_OUTPUT", "PLUME_MODELS", "STABILITY_CLASSES", "GaussianPlume", "PlumeConfig", "PlumePart", "PlumeSetup",
    "PuffPlume", "Source", "WindLike", "briggs_sigmas", "gaussian_plume_concentration", "make_plume",
    "parse_plume_table",
]
