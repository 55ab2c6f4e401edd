"""The recording listens to a running SITL: its truth and what arrives on its link, in one ``.rrd``.

``windseek sitl --rrd PATH`` attaches a :class:`LinkRecorder` to the SITL's link: the simulation's
truth through :func:`recording.sim_hook.record_simulation`, plus what only the wire knows: WIND_COV
(estimate, +-2 sigma band, speed and from-direction raw and low-passed, the estimate arrow at the
vehicle), the mission's strategy states and declared source (:mod:`wire.names`: the phases, path
colours and events), the geofence box given on the command line, and at close a run summary from
the truth. The wire's messages are read by :class:`recording.wire_rx.WireRecorder`, as with PX4 or
ArduPilot flying (:mod:`recording.autopilot_rrd`). It registers itself on the link's hooks (the
endpoint's ``rx_hooks``, the simulation's ``step_hooks``), which run in the link's own thread, so
nothing here needs a lock; the link knows nothing of it (the recording listens; nothing in ``sitl``
imports ``recording``).

Conventions: SI, NED, wind = air-mass velocity NED; simulation seconds.
"""

from __future__ import annotations

import bisect
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from recording.recorder import RunRecorder
from recording.sim_hook import record_simulation
from recording.stream import CpuMeter
from recording.summary import RunSummary
from recording.tally import FlightTally
from recording.wire_rx import WireRecorder

if TYPE_CHECKING:
    from sitl.link.endpoint import Link
    from sitl.link.runner import SitlLink
    from sitl.simulation import Simulation

class LinkRecorder:
    """The simulation's truth and what arrives on the wire (WIND_COV, mission status) into one ``.rrd``.

    The mission's STATUSTEXT states and its declaration (:mod:`wire.names`) drive the recording's
    phases, path colours and events exactly as an in-process trial's do; WIND_COV gives the wind
    estimate (with its +-2 sigma band) and the filtered direction. At close it writes a run summary
    from what the SITL knows (truth, the wire); ``windseek demo`` later completes it with the
    mission's own result (:mod:`recording.finalize`).

    Args:
        link: the SITL link (its thread runs every hook).
        path: the ``.rrd`` file.
        strategy: recording label (the mission's strategy, if known).
        geofence_ned: (min corner, max corner) of the mission's geofence box [m, NED], drawn static.
        field_altitude_m: height of the urban wind field's horizontal slice [m above the ground]
            (None: the scenario's take-off altitude).
        filter_cutoff_hz: cutoff of the first-order low-pass giving the "filtered" wind direction
            from the received estimates [Hz].
    """

    def __init__(self, link: SitlLink, path: Path | str, strategy: str | None = None,
                 geofence_ned: tuple[list[float], list[float]] | None = None,
                 filter_cutoff_hz: float = 0.05, field_altitude_m: float | None = None) -> None:  # fmt: skip
        sim = link.sim
        self.link = link
        self.strategy = strategy
        # Rates and sends chosen so the recording costs the SITL under 10 % of its CPU
        # (benchmarks/recording_cost.py): pose and true series at 5 Hz (the estimate at its own
        # rate), plume slices every 5 s, the buffered rows sent every 15 s of simulation (a live
        # viewer lags by that much).
        self.meter = CpuMeter()  # what recording costs this process: the recording_cost property
        self.t0 = sim.t
        self.rec: RunRecorder = self.meter(lambda: RunRecorder(path, scenario=sim.scenario.name, strategy=strategy,
                                                               seed=sim.seed, series_flush_s=15.0))  # fmt: skip
        if geofence_ned is not None:
            self.rec.geofence(*geofence_ned)
        # Metered: an urban scenario's buildings and wind field are logged here, once.
        self.meter(lambda: record_simulation(sim, self.rec, vehicle_hz=5.0, series_hz=5.0, slice_hz=0.2,
                                             field_altitude_m=field_altitude_m, meter=self.meter))  # fmt: skip
        self.tally = FlightTally([] if sim.chem is None else sim.chem.sources_ned)
        # The path (t, n, e, d) at every mode tick of the last 60 s: an estimate is scored against the
        # wind field at its nearest tick's time and position (estimates arrive late). The field is
        # evaluated only then, not every tick; positions are kept exactly because the turbulent field
        # changes by ~0.1 m/s over 0.1 m (an interpolated position would score the estimate wrongly).
        rate = sim.scenario.mode_rate_hz
        self.track: deque[tuple[float, float, float, float]] = deque(maxlen=max(1, int(60.0 * rate)))
        self.tally_every = max(1, round(rate / 10.0))  # the path length and phases' tally at 10 Hz
        self._k = -1
        self.wire = WireRecorder(self.rec, lambda: sim.t, lambda: sim.x[0:3], filter_cutoff_hz=filter_cutoff_hz)
        sim.step_hooks.append(lambda s: self.meter(self.on_tick, s))
        link.endpoint.rx_hooks.append(lambda msg, lk: self.meter(self.on_message, msg, lk))

    def on_tick(self, s: Simulation) -> None:
        """The vehicle's position at every mode tick (the true-wind lookups); the tally at 10 Hz."""
        x = s.x
        self.track.append((s.t, float(x[0]), float(x[1]), float(x[2])))
        self._k += 1
        if self._k % self.tally_every == 0:
            ph = self.rec.phases
            self.tally.position(x[0:3], ph.armed, ph.searching, ph.declared)

    def true_wind(self, t: float) -> tuple[np.ndarray, float] | None:
        """True wind [m/s NED] at the vehicle at the mode tick nearest to time ``t`` [s] and the height
        then [m], or None when no kept tick is within 0.1 s."""
        tr = self.track
        if not tr:
            return None
        i = bisect.bisect_left(tr, (t,))
        near = min((tr[j] for j in (i - 1, i) if 0 <= j < len(tr)), key=lambda r: abs(r[0] - t))
        if abs(near[0] - t) > 0.1:
            return None
        pos = np.array(near[1:])
        return np.asarray(self.link.sim.wind.velocity(near[0], pos), dtype=float), -float(pos[2])

    def on_message(self, msg: Any, lk: Link) -> None:
        got = self.wire.on_message(msg)
        # Every other estimate is scored against the truth: the field's lookup is costly.
        if got is not None and self.wire.estimates % 2 == 0 and (tr := self.true_wind(got[0])) is not None:
            self.tally.wind(got[1], tr[0], tr[1])

    def summary(self) -> RunSummary:
        """What the SITL knows of the run: truth, the wire's declaration, the phases it saw."""
        rec, ph = self.rec, self.rec.phases
        sim = self.link.sim
        s = RunSummary(kind="windseek sitl (truth and the wire)", scenario=sim.scenario.name,
                       strategy=self.strategy, seed=sim.seed, wind_source=self.wire.source_line())  # fmt: skip
        s.fill_from_phases(ph, rec.declaration is not None, self.link.sim.t)
        self.tally.fill(s)
        return s

    def close(self) -> None:
        rec = self.rec
        self.meter(lambda: rec.summary(self.summary()))
        self.meter(rec.close, lambda: {"sim_s": round(self.link.sim.t - self.t0, 3), **self.meter.report(rec)})


__all__ = ["LinkRecorder"]
