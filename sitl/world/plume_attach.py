"""Attach a chemical plume and a chemical sensor to a :class:`~sitl.simulation.Simulation`.

The scenario's raw ``[plume]`` TOML table (``Scenario.plume``) is parsed and validated
here (:func:`parse_plume_table`, called by ``sitl.scenario.parse_scenario`` so a bad file
fails at load time) and turned into a live model by :func:`attach_plume`, which
``Simulation.__init__`` calls when the scenario has a ``[plume]`` table.

TOML format (every key optional except ``sources``; defaults shown)::

    [plume]
    model = "puff"              # "puff" (instantaneous, Farrell) | "gaussian" (time-averaged)
    stability = "D"             # Pasquill-Gifford class "A" (very unstable) .. "F" (stable)
    puff_rate_hz = 10.0         # puffs released per second per source [Hz]
    max_puffs = 1000            # cap on live puffs (oldest removed first)
    update_rate_hz = 10.0       # plume integration rate [Hz]; must divide the mode rate
    warmup_s = 120.0            # plume formed before t = 0 [s] (built at t0 = -warmup_s)
    source_radius_m = 0.3       # initial puff standard deviation [m]
    min_wind_speed_m_s = 0.5    # wind-speed floor for dilution [m/s]
    subtract_wind_turbulence = true
    # domain_min_ned = [-100.0, -100.0, -50.0]   # optional box [m, NED]; both or neither
    # domain_max_ned = [400.0, 100.0, 0.0]
    sources = [{ position_ned = [60.0, 0.0, -2.0], rate_g_s = 1.0 }]
    #   per source: position_ned [m, NED, z <= 0], rate_g_s [g/s] (>= 0),
    #   start_s [s] (default -warmup_s: emitting since the warm-up began; start_s = 0
    #   switches the source on at t = 0, so the warm-up forms no plume), stop_s [s] (optional)

    [plume.sensor]              # sitl.world.chem_sensor.ChemSensorConfig fields
    time_constant_s = 0.5       # [s]
    noise_std_mg_m3 = 0.01      # [mg/m^3]
    detection_limit_mg_m3 = 0.05
    saturation_mg_m3 = 1000.0
    sample_rate_hz = 10.0       # [Hz]; must divide the mode rate
    initial_mg_m3 = 0.0

Timing: the attachment runs as a ``Simulation.step_hooks`` entry, i.e. at every mode tick
(``physics.mode_rate_hz``, 50 Hz by default), at ``sim.t`` with the state ``sim.x``. Both
the plume update rate and the sensor sample rate must divide the mode rate exactly
(50 Hz: 50, 25, 50/3, 12.5, 10, 50/6, ... , 1, ...), so every plume step and every reading
falls on a mode tick and the readings are evenly spaced at exactly the configured rate;
any other rate is rejected at load time (naming the field and the allowed values) rather
than silently resampled with jitter. At a due tick the plume is advanced to ``sim.t``
first and the sensor then samples the true concentration at the vehicle position
``sim.x[0:3]`` (NED, m) in that plume.

Seeding: the plume and the sensor noise are spawned (in that order) from
``sim._seed_extra``, the simulation's seed sequence reserved for extra models, so a run is
reproducible from the simulation seed alone.

Units: SI, NED world frame; wind = air-mass velocity NED (the plume is carried by
``sim.wind``, the same field the vehicle feels); release in g/s; concentration in mg/m^3.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

from sitl.scenario import ScenarioError, _num, _table, _vec3
from sitl.world.chem_sensor import ChemicalSensor, ChemReading, ChemSensorConfig
from sitl.world.plume import PLUME_MODELS, STABILITY_CLASSES, GaussianPlume, PlumeConfig, PuffPlume, Source, make_plume

if TYPE_CHECKING:
    from sitl.simulation import Simulation

#: Maximum number of chemical readings kept between two ``Simulation.drain()`` calls.
CHEM_QUEUE_MAXLEN: int = 100_000
#: Name of the readings queue in ``sim.outputs.extra`` / ``sim.drain()``.
CHEM_OUTPUT: str = "chem"

PLUME_KEYS: frozenset[str] = frozenset(
    {
        "model", "stability", "puff_rate_hz", "max_puffs", "update_rate_hz", "warmup_s", "sources",
        "domain_min_ned", "domain_max_ned", "source_radius_m", "min_wind_speed_m_s",
        "subtract_wind_turbulence", "sensor",
    }
)  # fmt: skip
SOURCE_KEYS: frozenset[str] = frozenset({"position_ned", "rate_g_s", "start_s", "stop_s"})
SENSOR_KEYS: frozenset[str] = frozenset(f.name for f in fields(ChemSensorConfig))


@dataclass(frozen=True)
class PlumeSetup:
    """A parsed ``[plume]`` table.

    plume: plume model configuration (source times in simulation seconds).
    sensor: chemical sensor configuration.
    warmup_s: how long the plume is integrated before t = 0 [s].
    """

    plume: PlumeConfig
    sensor: ChemSensorConfig
    warmup_s: float


# --------------------------------------------------------------------------- parsing
def _choice(name: str, value: Any, allowed: tuple[str, ...], hint: str) -> str:
    if value not in allowed:
        raise ScenarioError(f"{name} = {value!r}: allowed values are {hint}")
    return value


def _divisor_rate(name: str, value: Any, mode_rate_hz: float) -> float:
    """A rate [Hz] that divides the mode rate exactly (see module docstring, Timing)."""
    rate = _num(name, value, 1e-3, mode_rate_hz)
    n = mode_rate_hz / rate
    if abs(n - round(n)) > 1e-6:
        examples = ", ".join(f"{mode_rate_hz / k:g}" for k in (1, 2, 5, 10, 25, 50) if mode_rate_hz / k >= 1e-3)
        raise ScenarioError(
            f"{name} = {value!r}: must divide the {mode_rate_hz:g} Hz mode rate; allowed values are "
            f"{mode_rate_hz:g}/n Hz for integer n >= 1 (e.g. {examples})"
        )
    return rate


def _parse_source(name: str, value: Any, warmup_s: float) -> Source:
    tbl = _table(name, value, SOURCE_KEYS)
    for key in ("position_ned", "rate_g_s"):
        if key not in tbl:
            raise ScenarioError(f"{name}.{key}: required")
    pos = _vec3(f"{name}.position_ned", tbl["position_ned"])
    if pos[2] > 0.0:
        raise ScenarioError(f"{name}.position_ned[2] = {pos[2]}: must be <= 0 (NED: the ground is z = 0)")
    rate = _num(f"{name}.rate_g_s", tbl["rate_g_s"], 0.0, 1e6)
    start = _num(f"{name}.start_s", tbl.get("start_s", -warmup_s), -1e6, 1e6)
    stop = math.inf
    if "stop_s" in tbl:
        stop = _num(f"{name}.stop_s", tbl["stop_s"], -1e6, 1e6)
        if stop <= start:
            raise ScenarioError(f"{name}.stop_s = {stop}: must be > start_s = {start}")
    return Source(pos, rate, start, stop)


def parse_plume_table(tbl: Any, mode_rate_hz: float = 50.0) -> PlumeSetup:
    """Parse and validate a raw ``[plume]`` table (see the module docstring for the format).

    tbl: the table as read from TOML (dict).
    mode_rate_hz: the simulation's mode-tick rate [Hz]; plume and sensor rates must divide it.

    Raises ``sitl.scenario.ScenarioError`` naming the field (``plume.<key>``) and the
    allowed values.
    """
    tbl = _table("plume", tbl, PLUME_KEYS)
    model = _choice("plume.model", tbl.get("model", "puff"), PLUME_MODELS, ", ".join(repr(m) for m in PLUME_MODELS))
    stability = _choice(
        "plume.stability", tbl.get("stability", "D"), STABILITY_CLASSES,
        f"{STABILITY_CLASSES[0]}-{STABILITY_CLASSES[-1]} (Pasquill-Gifford)",
    )  # fmt: skip
    warmup = _num("plume.warmup_s", tbl.get("warmup_s", 120.0), 0.0, 3600.0)
    max_puffs = tbl.get("max_puffs", 1000)
    if isinstance(max_puffs, bool) or not isinstance(max_puffs, int) or not 1 <= max_puffs <= 1_000_000:
        raise ScenarioError(f"plume.max_puffs = {max_puffs!r}: allowed values are integers in [1, 1000000]")
    raw_sources = tbl.get("sources")
    if not isinstance(raw_sources, list) or not raw_sources:
        raise ScenarioError(
            "plume.sources: required, a non-empty list of "
            "{ position_ned = [n, e, d], rate_g_s = ..., start_s = ..., stop_s = ... } tables"
        )
    sources = tuple(_parse_source(f"plume.sources[{i}]", s, warmup) for i, s in enumerate(raw_sources))
    dom_lo = _vec3("plume.domain_min_ned", tbl["domain_min_ned"]) if "domain_min_ned" in tbl else None
    dom_hi = _vec3("plume.domain_max_ned", tbl["domain_max_ned"]) if "domain_max_ned" in tbl else None
    subtract = tbl.get("subtract_wind_turbulence", True)
    if not isinstance(subtract, bool):
        raise ScenarioError(f"plume.subtract_wind_turbulence = {subtract!r}: allowed values are true, false")
    plume = PlumeConfig(
        sources=sources,
        stability=stability,
        model=model,
        puff_rate_hz=_num("plume.puff_rate_hz", tbl.get("puff_rate_hz", 10.0), 1e-3, 1e4),
        max_puffs=max_puffs,
        update_rate_hz=_divisor_rate("plume.update_rate_hz", tbl.get("update_rate_hz", 10.0), mode_rate_hz),
        domain_min_ned=dom_lo,
        domain_max_ned=dom_hi,
        source_radius_m=_num("plume.source_radius_m", tbl.get("source_radius_m", 0.3), 1e-3, 100.0),
        min_wind_speed_m_s=_num("plume.min_wind_speed_m_s", tbl.get("min_wind_speed_m_s", 0.5), 1e-3, 100.0),
        subtract_wind_turbulence=subtract,
    )
    errors = plume.validate()
    if errors:  # what the per-key checks above cannot see (e.g. domain min >= max)
        raise ScenarioError("; ".join(f"plume.{e}" for e in errors))

    raw_sensor = _table("plume.sensor", tbl.get("sensor", {}), SENSOR_KEYS)
    kw: dict[str, float] = {}
    for key, value in raw_sensor.items():
        if key == "sample_rate_hz":
            kw[key] = _divisor_rate("plume.sensor.sample_rate_hz", value, mode_rate_hz)
        else:
            kw[key] = _num(f"plume.sensor.{key}", value, -1e9, 1e9)
    sensor = ChemSensorConfig(**kw)
    errors = sensor.validate()
    if errors:
        raise ScenarioError("; ".join(f"plume.sensor.{e}" for e in errors))
    return PlumeSetup(plume=plume, sensor=sensor, warmup_s=warmup)


# --------------------------------------------------------------------------- live model
class PlumeModel:
    """Plume + chemical sensor attached to a simulation (the handle :func:`attach_plume` returns).

    Attributes:
        setup: the parsed configuration.
        plume: the plume model (``PuffPlume`` or ``GaussianPlume``), at time ``plume.t`` [s].
        sensor: the chemical sensor at the vehicle position.
        latest: the most recent reading (None before the first).
        n_samples / n_detected: readings taken / at or above the detection limit.
        peak_mg_m3: largest reading so far [mg/m^3].
    """

    def __init__(self, sim: Simulation, setup: PlumeSetup) -> None:
        self.setup = setup
        ss_plume, ss_sensor = sim._seed_extra.spawn(2)
        dt_update = 1.0 / setup.plume.update_rate_hz
        n_warm = round(setup.warmup_s / dt_update)
        t0 = -n_warm * dt_update  # whole update periods, so plume steps stay on the grid
        self.plume: PuffPlume | GaussianPlume = make_plume(setup.plume, sim.wind, ss_plume, t0=t0)
        for i in range(n_warm):
            # Step between grid times (i - n_warm) * dt so the plume lands on t = 0 exactly
            # (accumulating t0 + i * dt would leave it a rounding error away from 0).
            ta, tb = (i - n_warm) * dt_update, (i + 1 - n_warm) * dt_update
            self.plume.step(ta, tb - ta)
        self.sensor = ChemicalSensor(setup.sensor, ss_sensor)
        mode_rate = sim.scenario.mode_rate_hz
        # Rates are validated to divide the mode rate, so these are exact integers.
        self._plume_every = round(mode_rate / setup.plume.update_rate_hz)
        self._sensor_every = round(mode_rate / setup.sensor.sample_rate_hz)
        self.latest: ChemReading | None = None
        self.n_samples = 0
        self.n_detected = 0
        self.peak_mg_m3 = 0.0
        self._queue: deque = deque(maxlen=CHEM_QUEUE_MAXLEN)
        sim.outputs.extra[CHEM_OUTPUT] = self._queue

    def on_mode_tick(self, sim: Simulation) -> None:
        """Step hook: advance the plume and sample the sensor when due (see module Timing)."""
        k = sim.tick // sim.mode_div
        t = sim.t
        if k % self._plume_every == 0 and t > self.plume.t:
            self.plume.step(self.plume.t, t - self.plume.t)
        if k % self._sensor_every == 0:
            true_c = self.plume.concentration(sim.x[0:3])
            reading = self.sensor.sample(t, true_c)
            self.latest = reading
            sim.chem_latest = reading
            self._queue.append(reading)
            self.n_samples += 1
            self.n_detected += reading.detected
            self.peak_mg_m3 = max(self.peak_mg_m3, reading.value_mg_m3)

    @property
    def n_puffs(self) -> int:
        """Live puffs (0 for the Gaussian model)."""
        return len(self.plume.puffs) if isinstance(self.plume, PuffPlume) else 0

    def summary(self, sim: Simulation) -> dict[str, object]:
        """Summary hook: plume_puffs, chem_peak [mg/m^3], chem_detect_fraction (of all readings)."""
        frac = self.n_detected / self.n_samples if self.n_samples else 0.0
        return {
            "plume_puffs": self.n_puffs,
            "chem_peak": round(float(self.peak_mg_m3), 6),
            "chem_samples": self.n_samples,
            "chem_detect_fraction": round(frac, 6),
        }


def attach_plume(sim: Simulation) -> PlumeModel:
    """Build the scenario's plume on ``sim.wind``, warm it up and hook it into ``sim``.

    Sets ``sim.plume`` (the plume model), ``sim.chem_sensor`` and ``sim.chem_latest``
    (latest ``ChemReading`` or None), ``sim.plume_model`` (the returned handle); registers
    the step hook and the summary hook; readings go to ``sim.outputs.extra["chem"]``.
    Raises ScenarioError if the scenario has no valid ``[plume]`` table.
    """
    if sim.scenario.plume is None:
        raise ScenarioError("[plume]: the scenario has no plume table")
    setup = parse_plume_table(sim.scenario.plume, sim.scenario.mode_rate_hz)
    model = PlumeModel(sim, setup)
    sim.plume = model.plume
    sim.chem_sensor = model.sensor
    sim.chem_latest = None
    sim.plume_model = model
    sim.step_hooks.append(model.on_mode_tick)
    sim.summary_hooks.append(model.summary)
    return model


__all__ = [
    "CHEM_OUTPUT",
    "PlumeModel",
    "PlumeSetup",
    "attach_plume",
    "parse_plume_table",
]
