"""The built-in wind model: a steady wind (schedule, height profile) plus optional Kaimal turbulence.

:class:`WindField` binds a :class:`~sitl.world.wind.steady.SteadyWind`, an optional
:class:`~sitl.world.wind.turbulence.KaimalTurbulence` and a seed. Sampling goes through the numba
kernels of :mod:`sitl.world.wind.kernel`, the single implementation; the simulator's physics loop
calls them directly with :meth:`WindField.kernel`.

Units: m, s, m/s; NED; wind = air-mass velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sitl.world.wind.kernel import WindKernel, wind_mean, wind_velocity, wind_velocity_many
from sitl.world.wind.steady import SteadyWind
from sitl.world.wind.turbulence import KaimalTurbulence


@dataclass(eq=False)
class WindField:
    """Steady wind + optional Kaimal turbulence, seeded; what the vehicle, the plume and the
    estimator's truth sample (it satisfies :class:`~sitl.world.wind.model.WindModel`).

    Args:
        steady: mean wind, schedule and profile.
        turbulence: Kaimal turbulence or None for a steady field.
        seed: int or ``np.random.SeedSequence`` for the turbulence noise.

    The turbulence spectra use U = ``turbulence.mean_speed_ms`` if given, else the horizontal
    speed of ``steady.velocity_ned`` (the initial wind at the reference height).
    """

    steady: SteadyWind
    turbulence: KaimalTurbulence | None
    seed: int | np.random.SeedSequence
    turbulence_series: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = field(init=False, default=None)
    turbulence_mean_speed_ms: float = field(init=False, default=0.0)
    _kernel: WindKernel = field(init=False, repr=False)

    def __post_init__(self) -> None:
        sched_t, sched_vel = self.steady.schedule_arrays()
        z0 = self.steady.roughness_length_m
        inv_log_ref = 1.0 / math.log(self.steady.reference_height_m / z0)
        turb = self.turbulence
        if turb is None:
            uvw = np.zeros((0, 3), dtype=np.float64)
            turb_on, taylor, rate = False, False, 1.0
        else:
            if turb.mean_speed_ms is not None:
                u_mean = turb.mean_speed_ms
            else:
                u_mean = math.hypot(self.steady.velocity_ned[0], self.steady.velocity_ned[1])
            self.turbulence_mean_speed_ms = float(u_mean)
            rng = np.random.default_rng(self.seed)
            series = turb.synthesize(u_mean, rng)
            self.turbulence_series = series
            uvw = np.ascontiguousarray(np.stack(series[1:], axis=1))
            turb_on, taylor, rate = True, turb.taylor, float(turb.sample_rate_hz)
        self._kernel = WindKernel(sched_t, sched_vel, self.steady.profile == "log", float(z0), float(inv_log_ref),
                                  turb_on, taylor, rate, uvw)  # fmt: skip

    @property
    def reference_height_m(self) -> float:
        """Height at which the schedule's velocities hold, m."""
        return self.steady.reference_height_m

    def kernel(self) -> WindKernel:
        """The numba fast path: the parameters :func:`~sitl.world.wind.kernel.wind_velocity` reads.
        Its arrays are the field's own (writing ``sched_vel`` changes the wind from now on)."""
        return self._kernel

    def mean(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Mean air-mass velocity (3,) m/s NED at NED point ``pos_ned`` (3,) m, time t s."""
        pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
        if pos.shape != (3,):
            raise ValueError(f"pos_ned must have shape (3,) (m, NED), got {pos.shape}")
        return wind_mean(float(t), pos, self._kernel)

    def velocity(self, t: float, pos_ned: np.ndarray) -> np.ndarray:
        """Air-mass velocity (mean + turbulence), m/s NED, at NED point(s) ``pos_ned`` (m).

        ``pos_ned`` of shape (3,) gives (3,); shape (N, 3) gives (N, 3).
        """
        pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
        if pos.shape == (3,):
            return wind_velocity(float(t), pos, self._kernel)
        if pos.ndim == 2 and pos.shape[1] == 3:
            return wind_velocity_many(float(t), pos, self._kernel)
        raise ValueError(f"pos_ned must have shape (3,) or (N, 3) (m, NED), got {pos.shape}")
