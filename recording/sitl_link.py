"""The recording listens to a running SITL: its truth and what arrives on its link, in one ``.rrd``.

``windseek sitl --rrd PATH`` attaches a :class:`LinkRecorder` to the SITL's link: the simulation's
truth through :func:`recording.sim_hook.record_simulation`, plus what only the wire knows: WIND_COV
(estimate, +-2 sigma band, speed and from-direction raw and low-passed, the estimate arrow at the
vehicle), the mission's strategy states and declared source (:mod:`wire.names`: the phases, path
colours and events), the geofence box given on the command line, and at close a run summary from
the truth. It registers itself on the link's hooks (the endpoint's ``rx_hooks``, the simulation's
``step_hooks``), which run in the link's own thread, so nothing here needs a lock; the link knows
nothing of it (the recording listens; nothing in ``sitl`` imports ``recording``).

Conventions: SI, NED, wind = air-mass velocity NED; simulation seconds.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from recording.recorder import RunRecorder
from recording.sim_hook import record_simulation
from recording.stream import CpuMeter
from recording.summary import RunSummary
from recording.tally import FlightTally
from wire.names import ESTIMATOR_COMPONENT, MISSION_COMPONENT, SRC_CONF, SRC_NAMES, STATE_PREFIX

if TYPE_CHECKING:
    from sitl.link.endpoint import Link
    from sitl.link.runner import SitlLink
    from sitl.simulation import Simulation

#: The autopilot's own (system, component): its STATUSTEXT is not the mission's.
AUTOPILOT_ID = (1, 1)


def _name(msg: Any) -> str:
    return str(getattr(msg, "name", "")).rstrip("\x00")


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
        self.tau_s = 1.0 / (2.0 * math.pi * filter_cutoff_hz)
        self._filt: np.ndarray | None = None
        self._t_filt = 0.0
        self.estimates = 0
        self.wind_from: tuple[int, int] | None = None
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
        mtype = msg.get_type()
        sim, rec = self.link.sim, self.rec
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if mtype == "WIND_COV":
            t = msg.time_usec * 1e-6
            wx, wy, wz = float(msg.wind_x), float(msg.wind_y), float(msg.wind_z)
            if not (math.isfinite(wx) and math.isfinite(wy) and math.isfinite(wz)):
                return
            w = np.array([wx, wy, wz])
            self.estimates += 1
            self.wind_from = src
            sh = math.sqrt(max(float(msg.var_horiz), 0.0) / 2.0)
            sv = math.sqrt(max(float(msg.var_vert), 0.0))
            rec.wind(t, est_ned=w, sigma_ned=[sh, sh, sv])
            rec.wind_arrows(t, sim.x[0:3], None, w)
            if self._filt is None:
                self._filt = w[:2].copy()
            else:
                a = min(1.0, max(0.0, t - self._t_filt) / self.tau_s)
                self._filt += a * (w[:2] - self._filt)
            self._t_filt = t
            fn, fe = float(self._filt[0]), float(self._filt[1])
            # From-directions with math (vehicle.frames.from_direction_deg's numpy costs ~40 us a call).
            rec.wind_speed_dir(t, math.hypot(wx, wy), math.degrees(math.atan2(-wy, -wx)) % 360.0,
                               math.hypot(fn, fe), math.degrees(math.atan2(-fe, -fn)) % 360.0)  # fmt: skip
            tr = self.true_wind(t) if self.estimates % 2 == 0 else None  # every other one: the field is costly
            if tr is not None:
                self.tally.wind(w, tr[0], tr[1])
        elif mtype == "STATUSTEXT":
            if src == AUTOPILOT_ID:
                return
            text = str(msg.text).rstrip("\x00")
            who = {MISSION_COMPONENT: "mission", ESTIMATOR_COMPONENT: "estimator"}.get(src[1], f"{src[0]}:{src[1]}")
            if text.startswith(STATE_PREFIX):
                who = "mission"
            rec.mission_statustext(sim.t, text, who, "WARN" if msg.severity <= 4 else "INFO")
        elif mtype == "NAMED_VALUE_FLOAT":
            name = _name(msg)
            if name in SRC_NAMES or name == SRC_CONF:
                # The mission stamps its declaration with its own tick time (vehicle time).
                rec.mission_named_value(msg.time_boot_ms * 1e-3, name, float(msg.value))

    def summary(self) -> RunSummary:
        """What the SITL knows of the run: truth, the wire's declaration, the phases it saw."""
        rec, ph = self.rec, self.rec.phases
        src = "none received" if self.wind_from is None else \
            f"WIND_COV from system {self.wind_from[0]} component {self.wind_from[1]} ({self.estimates} received)"
        s = RunSummary(kind="windseek sitl (truth and the wire)", scenario=self.link.sim.scenario.name,
                       strategy=self.strategy, seed=self.link.sim.seed, wind_source=src)  # fmt: skip
        if math.isfinite(ph.t_declared) and math.isfinite(ph.t_arm):
            s.time_to_declaration_s = round(ph.t_declared - ph.t_arm, 2)
        if math.isfinite(ph.t_arm):
            end = ph.t_disarm if math.isfinite(ph.t_disarm) else self.link.sim.t
            s.mission_time_s = round(end - ph.t_arm, 2)
        if rec.declaration is None and self.strategy:
            s.cause = "no declaration received"
        self.tally.fill(s)
        return s

    def close(self) -> None:
        rec = self.rec
        self.meter(lambda: rec.summary(self.summary()))
        self.meter(rec.close, lambda: {"sim_s": round(self.link.sim.t - self.t0, 3), **self.meter.report(rec)})


__all__ = ["LinkRecorder"]
