"""The plume and the chemical sensor as one part of the world (:class:`PlumePart`).

Timing: the world calls :meth:`PlumePart.on_slow_tick` at every slow tick (``physics.mode_rate_hz``,
50 Hz by default) with the tick index, the time and the vehicle position. Both the plume update
rate and the sensor sample rate divide the slow-tick rate exactly (the ``[plume]`` parser
refuses any other rate, naming the field), so every plume step and every reading falls on a
slow tick and the readings are evenly spaced at exactly the configured rate. At a due tick the
plume is advanced to ``t`` first and the sensor then samples the true concentration at the
vehicle position (NED, m) in that plume.

Seeding: the plume and the sensor noise are spawned (in that order) from the seed sequence the
world reserves for its plume, so a run is reproducible from the simulation seed alone.

Units: SI, NED world frame; wind = air-mass velocity NED (the plume is carried by the world's
wind model, the same field the vehicle feels); release in g/s; concentration in mg/m^3.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from sitl.world.chem_sensor import ChemicalSensor, ChemReading
from sitl.world.plume.config import WindLike
from sitl.world.plume.gaussian import GaussianPlume
from sitl.world.plume.puffs import PuffPlume, make_plume
from sitl.world.plume.setup import PlumeSetup

#: Maximum number of chemical readings kept between two ``drain()`` calls (oldest dropped).
CHEM_QUEUE_MAXLEN: int = 100_000
#: Name of the readings queue in ``drain()``.
CHEM_OUTPUT: str = "chem"


class PlumePart:
    """A plume formed over its warm-up before t = 0, and the chemical sensor on the vehicle.

    Attributes:
        setup: the parsed configuration.
        model: the plume model (``PuffPlume`` or ``GaussianPlume``), at time ``model.t`` [s].
        sensor: the chemical sensor at the vehicle position.
        latest: the most recent reading (None before the first).
        readings: readings since the last drain (bounded: the oldest are dropped past
            ``CHEM_QUEUE_MAXLEN``).
        n_samples / n_detected: readings taken / at or above the detection limit.
        peak_mg_m3: largest reading so far [mg/m^3].
    """

    def __init__(self, setup: PlumeSetup, wind: WindLike, seed: np.random.SeedSequence, slow_rate_hz: float) -> None:
        self.setup = setup
        ss_plume, ss_sensor = seed.spawn(2)
        dt_update = 1.0 / setup.plume.update_rate_hz
        n_warm = round(setup.warmup_s / dt_update)
        t0 = -n_warm * dt_update  # whole update periods, so plume steps stay on the grid
        self.model: PuffPlume | GaussianPlume = make_plume(setup.plume, wind, ss_plume, t0=t0)
        for i in range(n_warm):
            # Step between grid times (i - n_warm) * dt so the plume lands on t = 0 exactly
            # (accumulating t0 + i * dt would leave it a rounding error away from 0).
            ta, tb = (i - n_warm) * dt_update, (i + 1 - n_warm) * dt_update
            self.model.step(ta, tb - ta)
        self.sensor = ChemicalSensor(setup.sensor, ss_sensor)
        # Rates are validated to divide the slow-tick rate, so these are exact integers.
        self._plume_every = round(slow_rate_hz / setup.plume.update_rate_hz)
        self._sensor_every = round(slow_rate_hz / setup.sensor.sample_rate_hz)
        self.latest: ChemReading | None = None
        self.n_samples = 0
        self.n_detected = 0
        self.peak_mg_m3 = 0.0
        self.readings: deque[ChemReading] = deque(maxlen=CHEM_QUEUE_MAXLEN)

    @property
    def sources_ned(self) -> np.ndarray:
        """(S, 3) true source positions, m NED (for scoring and recording; strategies never see it)."""
        return np.array([s.position_ned for s in self.setup.plume.sources], dtype=float)

    def on_slow_tick(self, k: int, t: float, pos_ned: np.ndarray) -> None:
        """Slow tick ``k`` at time ``t`` [s]: advance the plume and sample the sensor at ``pos_ned`` when due."""
        if k % self._plume_every == 0 and t > self.model.t:
            self.model.step(self.model.t, t - self.model.t)
        if k % self._sensor_every == 0:
            reading = self.sensor.sample(t, float(self.model.concentration(pos_ned)))
            self.latest = reading
            self.readings.append(reading)
            self.n_samples += 1
            self.n_detected += reading.detected
            self.peak_mg_m3 = max(self.peak_mg_m3, reading.value_mg_m3)

    def puff_array(self) -> np.ndarray | None:
        """(K, 4) live puffs (x, y, z NED m, r^2 m^2) of the puff model; None for the Gaussian model."""
        return self.model.puffs if isinstance(self.model, PuffPlume) else None

    @property
    def n_puffs(self) -> int:
        """Live puffs (0 for the Gaussian model)."""
        return len(self.model.puffs) if isinstance(self.model, PuffPlume) else 0

    def summary(self) -> dict[str, object]:
        """plume_puffs, chem_peak [mg/m^3], chem_samples, chem_detect_fraction (of all readings)."""
        frac = self.n_detected / self.n_samples if self.n_samples else 0.0
        return {
            "plume_puffs": self.n_puffs,
            "chem_peak": round(float(self.peak_mg_m3), 6),
            "chem_samples": self.n_samples,
            "chem_detect_fraction": round(frac, 6),
        }
