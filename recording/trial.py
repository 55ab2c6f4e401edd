"""Record an in-process trial (:func:`mission.runners.inprocess.run_trial`) to a ``.rrd``.

``run_trial(..., recorder=TrialRecorder(path))`` attaches the recorder once the simulation, the
lockstep vehicle and the strategy exist, and hands it the trial's result at the end:

- the simulation's truth through :func:`recording.sim_hook.record_simulation` (in an urban
  scenario also the buildings and the mean wind field, its slice at the strategy's ``altitude_m``);
- the mission's status exactly as a MAVSDK runner sends it over MAVLink (the vehicle's
  ``publish``: strategy states, the declaration), so phases and events read the same as in
  ``windseek demo`` recordings;
- the wind the strategy used (estimate, +-2 sigma, raw and filtered direction) at ``series_hz``,
  and its error against the truth while airborne (scored at the same ticks);
- a probabilistic strategy's source posterior (``posterior_map()`` / ``credible_region()``, see
  :func:`record_posterior`) at ``posterior_hz``;
- the run summary from the :class:`~mission.runners.inprocess.TrialResult`.

From the command line (a quick look at one trial)::

    python -m mission.runners.record_trial open-field surge-cast --seed 1000 -o logs/trial.rrd

Times are simulation seconds (the vehicle's clock; the trial arms at t = 0).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from recording.recorder import RunRecorder
from recording.sim_hook import record_simulation, wind_speed_from_deg
from recording.stream import CpuMeter
from recording.summary import RunSummary
from recording.tally import FlightTally

SRC = ("SRC_N", "SRC_E", "SRC_D")
WIND_SOURCES = {"estimated": "the UKF on the simulated IMU, ESC and GNSS samples (in-process)",
                "oracle": "the simulator's true mean wind (oracle, comparison only)",
                "none": "none: pure chemotaxis"}  # fmt: skip


def record_posterior(rec: RunRecorder, t: float, strategy: object, cell_m: float = 1.0) -> bool:
    """Log ``strategy``'s source posterior on the map if it has one: ``posterior_map(cell_m)`` ->
    (P[i north, j east], (north_min, north_max, east_min, east_max) [m]) or None, and optionally
    ``credible_region()`` -> ((north, east) [m], radius [m]) or None. True when something was logged."""
    fn = getattr(strategy, "posterior_map", None)
    if fn is None:
        return False
    got = fn(cell_m)
    if got is None:
        return False
    p, extent = got
    region = getattr(strategy, "credible_region", None)
    rec.posterior(t, p, extent, region() if region is not None else None)
    return True


class TrialRecorder:
    """Records one in-process trial (see the module docstring); rates in Hz (lower than the SITL's
    defaults: a lockstep trial runs many times faster than real time, and the recording must stay
    within 10 % of its cost, ``benchmarks/recording_cost.py``: the plume's slices every 10 s, the
    SITL's every 5 s, as the two slices and their images are a fifth of the recorder's CPU),
    ``**recorder_kw`` for :class:`RunRecorder`."""

    def __init__(self, path: Path | str, *, vehicle_hz: float = 5.0, series_hz: float = 5.0,
                 slice_hz: float = 0.1, posterior_hz: float = 1.0, posterior_cell_m: float = 1.0,
                 **recorder_kw: Any) -> None:  # fmt: skip
        self.path = Path(path)
        self.rates = {"vehicle_hz": vehicle_hz, "series_hz": series_hz, "slice_hz": slice_hz}
        self.posterior_dt = 1.0 / posterior_hz if posterior_hz > 0 else math.inf
        self.posterior_cell_m = posterior_cell_m
        # A trial runs many times faster than real time and nobody watches it live: the buffered
        # rows, the static data and the layout are sent once, at the end (a send costs ~0.1 ms per
        # entity whatever its rows, and every chunk ~3 kB of the file; a 600 s trial's rows are
        # ~1 MB of memory); and the file has no footer (rerun's chunk manifest for random access, a
        # quarter of the file: recording.stream.RecorderBase).
        self.recorder_kw = {"series_flush_s": math.inf, "live_layout": False, "footer": False, **recorder_kw}
        self.rec: RunRecorder | None = None
        self._t_post = -math.inf
        self._src: dict[str, float] = {}
        self.series_dt = 1.0 / series_hz if series_hz > 0 else math.inf
        self._t_series = -math.inf

    def attach(self, sim: Any, vehicle: Any, strategy: Any, params: Any = None) -> None:
        """Start recording ``sim`` flown by ``vehicle`` (a ``LockstepVehicle``) with ``strategy``."""
        self.meter = CpuMeter()  # what recording costs the trial: the recording_cost property
        self.sim, self.vehicle, self.strategy = sim, vehicle, strategy
        self.home = np.asarray(sim.position, dtype=float).copy()
        self.tally = FlightTally([] if sim.chem is None else sim.chem.sources_ned)
        self.rec = rec = self.meter(lambda: RunRecorder(self.path, scenario=sim.scenario.name, seed=sim.seed,
                                                        strategy=getattr(strategy, "name", None), **self.recorder_kw))
        alt = getattr(params, "altitude_m", None)  # the search altitude: the urban wind field's slice
        self.meter(lambda: record_simulation(sim, rec, vehicle_hz=self.rates["vehicle_hz"],
                                             series_hz=self.rates["series_hz"], slice_hz=self.rates["slice_hz"],
                                             field_altitude_m=alt, meter=self.meter))  # fmt: skip
        publish = vehicle.publish

        def record(pairs: list[tuple[str, str]]) -> None:
            for name, fields in pairs:
                self._on_status(sim.t, name, json.loads(fields))

        def tapped(pairs: list[tuple[str, str]]) -> None:
            publish(pairs)
            self.meter(record, pairs)

        vehicle.publish = tapped  # what a MAVSDK runner would send over MAVLink
        vehicle.tick_hooks.append(lambda t: self.meter(self._tick, t))

    def _on_status(self, t: float, name: str, f: dict[str, Any]) -> None:
        rec = self.rec
        assert rec is not None
        if name == "STATUSTEXT":
            rec.mission_statustext(t, str(f.get("text", "")))
        elif name == "NAMED_VALUE_FLOAT":
            key = str(f.get("name", ""))
            if key in SRC:
                self._src[key] = float(f["value"])
            elif key == "SRC_CONF" and all(k in self._src for k in SRC):
                region = getattr(self.strategy, "credible_region", None)
                got = region() if region is not None else None
                rec.declare(t, [self._src[k] for k in SRC], float(f["value"]), None if got is None else got[1])

    def _tick(self, t: float) -> None:
        rec, sim = self.rec, self.sim
        assert rec is not None
        pos = sim.x[0:3]  # a view: the tally copies what it keeps
        ph = rec.phases
        self.tally.position(pos, ph.armed, ph.searching, ph.declared)
        wi = self.vehicle.wind_info
        if wi is not None and t - self._t_series >= self.series_dt - 1e-9:
            self._t_series = t
            est = wi.wind_ned
            cov = wi.cov_ned
            sigma = None if cov is None else [math.sqrt(max(float(cov[k][k]), 0.0)) for k in range(3)]
            rec.wind(t, est_ned=est, sigma_ned=sigma)
            speed, from_deg = wind_speed_from_deg(est)
            filt = math.degrees(wi.upwind_rad) if math.isfinite(wi.upwind_rad) else None
            rec.wind_speed_dir(t, speed, from_deg, None, filt)
            self.tally.wind(est, sim.last_wind[1], -(pos[2] - self.home[2]))
        if t - self._t_post >= self.posterior_dt - 1e-9:
            self._t_post = t
            record_posterior(rec, t, self.strategy, self.posterior_cell_m)

    def summary(self, result: Any) -> RunSummary:
        """The run summary of a finished trial (``TrialResult``)."""
        rec = self.rec
        assert rec is not None
        t_arm = rec.phases.t_arm if math.isfinite(rec.phases.t_arm) else 0.0
        err = result.error_m if math.isfinite(result.error_m) else None
        t_dec = result.time_s if math.isfinite(result.time_s) else None
        s = RunSummary(
            kind="in-process trial (mission.runners.inprocess)", scenario=result.scenario, strategy=result.strategy,
            seed=result.seed, wind_source=WIND_SOURCES.get(result.wind, result.wind), found=bool(result.success),
            outcome=(f"declared {err:.1f} m from the true source" if result.success else
                     f"{result.cause}" + (f": declared {err:.1f} m from the true source" if err is not None else "")),
            cause=result.cause or "declared", declared_ned=result.declared_ned,
            confidence=result.confidence if result.declared_ned is not None else None,
            true_sources_ned=rec.true_sources_ned, error_m=err, t_declared_s=t_dec,
            time_to_declaration_s=None if t_dec is None else round(t_dec - t_arm, 2),
            mission_time_s=round(self.sim.t - t_arm, 2), search_path_m=round(result.path_m, 2),
            start_distance_m=round(result.start_distance_m, 2),
            reach_path_m=result.reach_path_m if math.isfinite(result.reach_path_m) else None,
            verifications=[dict(v) for v in result.verifications],
            notes=["the trial stops at the declaration (batch evaluation: no landing)"],
        )  # fmt: skip
        self.tally.fill(s)  # total path and wind RMSE from the truth
        return s

    def finish(self, result: Any) -> None:
        """Write the summary of ``result`` and close the recording."""
        rec = self.rec
        if rec is None:
            return
        self.meter(lambda: rec.summary(self.summary(result), write=False))  # close writes it
        self.meter(rec.close, lambda: {"sim_s": round(self.sim.t, 3), **self.meter.report(rec)})


__all__ = ["TrialRecorder", "WIND_SOURCES", "record_posterior"]
