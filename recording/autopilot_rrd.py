"""The recording of a run PX4 or ArduPilot flies: windseek's truth, the companions' messages and the autopilot's
own wind estimate, in one ``.rrd``.

``windseek sitl SCENARIO --px4 --rrd PATH`` and ``--ardupilot --rrd PATH`` attach an
:class:`AutopilotRecorder` to the runner (:class:`sitl.hil.runner.HilRunner`,
:class:`sitl.ardupilot.runner.JsonRunner`). It listens and nothing in ``sitl`` knows it:

- the bridge's ``step_hooks`` (at its truth samples, the mode rate, 50 Hz): the truth through
  :func:`recording.sim_hook.record_world`, the same hook the built-in SITL's recording uses (pose,
  path, true wind and rotors at 5 Hz, every chemical reading, the plume every 5 s, the arming that
  the autopilot's outputs say), and the path's tally at 10 Hz;
- the runner's ``rx_hooks`` (what the autopilot passes windseek's peripheral component 158):
  :class:`recording.wire_rx.WireRecorder` with the autopilot's label, so windseek's estimate (WIND_COV
  from the estimator, "windseek UKF", with its +-2 sigma band) and the autopilot's own ("PX4 EKF2":
  its WIND_COV; "ArduCopter EKF3": its WIND) share the wind plots with the truth; the mission's
  states and declaration; the autopilot's flight mode and messages.

At close: a run summary with windseek's estimator's wind figures and the autopilot's, both scored
against the truth by the bridge (:class:`sitl.hil.summary.TruthScore`); the whole score is kept as
the recording property ``truth_score`` (JSON, without its per-second series). Rates are those of
``windseek sitl --rrd`` so that the recording costs the lockstep little: nothing runs per physics
frame but the bridge's own truth-sample counter check; every hook and message is CPU-metered
(``recording_cost``).

Conventions: SI, NED, wind = air-mass velocity NED; simulation seconds (= the autopilot's clock in lockstep).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from recording.recorder import RunRecorder
from recording.sim_hook import record_world
from recording.stream import CpuMeter
from recording.summary import RunSummary
from recording.tally import FlightTally
from recording.wire_rx import WireRecorder
from wire.jsonsafe import json_safe

if TYPE_CHECKING:
    from sitl.ardupilot.runner import JsonRunner
    from sitl.hil.runner import HilRunner

#: The name of windseek's estimate in the legends, beside the autopilot's.
ESTIMATE_LABEL = "windseek UKF"
#: The autopilot's own estimate, by who flies.
PX4_LABEL = "PX4 EKF2"
ARDUCOPTER_LABEL = "ArduCopter EKF3"


def _armed(bridge: Any) -> tuple[object, bool]:
    """No flight mode from the world (the HEARTBEAT gives it); armed as the autopilot's outputs say."""
    return None, bool(bridge.guard.armed)


def _rmse_line(d: dict[str, Any]) -> str:
    """One line of a :class:`sitl.hil.wind_score.WindScore` dict: RMSE N/E/D, of 1-s means, coverage."""
    if not d.get("scored"):
        return f"not scored ({d.get('received', 0)} received, none while airborne with truth at its time)"
    r, r1 = d["rmse_ned_m_s"], d["rmse_1s_ned_m_s"]
    out = (f"{d['rmse_horizontal_m_s']:.2f} m/s horizontal (N {r[0]:.2f}, E {r[1]:.2f}, D {r[2]:.2f}; "
           f"{d['scored']} of {d['received']} estimates while airborne)")  # fmt: skip
    if d.get("rmse_1s_horizontal_m_s") is not None:
        out += f"; of 1-s means {d['rmse_1s_horizontal_m_s']:.2f} (N {r1[0]:.2f}, E {r1[1]:.2f}, D {r1[2]:.2f})"
    if d.get("coverage_95_horizontal") is not None:
        out += f"; inside its 95 % circle {100 * d['coverage_95_horizontal']:.0f} %"
    return out


class AutopilotRecorder:
    """windseek's truth and what PX4 or ArduPilot pass on, into one ``.rrd`` (see the module docstring).

    Args:
        runner: the HIL or JSON runner (its ``bridge`` has ``step_hooks``, itself ``rx_hooks``).
        path: the ``.rrd`` file.
        autopilot: what the autopilot's own estimate is called (:data:`PX4_LABEL`, :data:`ARDUCOPTER_LABEL`).
        strategy: the mission's strategy, if known (recording label).
        geofence_ned: (min corner, max corner) of the mission's geofence box [m, NED], drawn static.
        field_altitude_m: height of the urban wind field's horizontal slice [m above the ground].
        filter_cutoff_hz: cutoff of the low-pass of the "filtered" wind direction [Hz].
    """

    def __init__(self, runner: HilRunner | JsonRunner, path: Path | str, autopilot: str, strategy: str | None = None,
                 geofence_ned: tuple[list[float], list[float]] | None = None, field_altitude_m: float | None = None,
                 filter_cutoff_hz: float = 0.05) -> None:  # fmt: skip
        b = runner.bridge
        self.bridge, self.autopilot, self.strategy = b, autopilot, strategy
        self.meter = CpuMeter()
        self.t0 = b.t
        self.rec: RunRecorder = self.meter(lambda: RunRecorder(
            path, scenario=b.scenario.name, strategy=strategy, seed=b.world.seed, series_flush_s=15.0,
            estimate_label=ESTIMATE_LABEL, autopilot_label=autopilot))  # fmt: skip
        if geofence_ned is not None:
            self.rec.geofence(*geofence_ned)
        truth = self.meter(lambda: record_world(b, self.rec, status=_armed, vehicle_hz=5.0, series_hz=5.0,
                                                slice_hz=0.2, field_altitude_m=field_altitude_m, meter=self.meter))
        plume = b.world.plume
        self.tally = FlightTally([] if plume is None else plume.sources_ned)
        self.tally_every = max(1, round(b.scenario.mode_rate_hz / 10.0))  # the path's tally at 10 Hz
        self._k = -1
        b.step_hooks.append(truth)
        b.step_hooks.append(self.on_tick)
        self.wire = WireRecorder(self.rec, lambda: b.t, lambda: b.world.x[0:3], autopilot_label=autopilot,
                                 filter_cutoff_hz=filter_cutoff_hz)  # fmt: skip
        runner.rx_hooks.append(lambda m: self.meter(self.wire.on_message, m))

    def on_tick(self, bridge: Any) -> None:
        """The path's tally (total, search, until near the source) at 10 Hz of the truth samples."""
        self._k += 1
        if self._k % self.tally_every == 0:
            ph = self.rec.phases
            self.tally.position(bridge.world.x[0:3], ph.armed, ph.searching, ph.declared)

    def score(self) -> dict[str, Any]:
        """The bridge's score of both estimates against the truth (:meth:`TruthScore.to_dict`)."""
        plume = self.bridge.world.plume
        srcs = [] if plume is None else [[float(v) for v in p] for p in plume.sources_ned]
        return dict(self.bridge.truth.to_dict(srcs))

    def summary(self, d: dict[str, Any]) -> RunSummary:
        """The run summary from the truth and the wire; ``d``: :meth:`score`."""
        rec, ph = self.rec, self.rec.phases
        s = RunSummary(kind=f"windseek sitl, {self.autopilot.split()[0]} flying (truth and the wire)",
                       scenario=self.bridge.scenario.name, strategy=self.strategy, seed=self.bridge.world.seed,
                       wind_source=self.wire.source_line())  # fmt: skip
        if d["wind_estimates_scored"]:
            s.wind_rmse_ned_m_s, s.wind_scored = d["wind_rmse_ned_m_s"], d["wind_estimates_scored"]
            s.wind_rmse_horizontal_m_s = d["wind_rmse_horizontal_m_s"]
        est = {"received": d["wind_estimates_received"], "scored": d["wind_estimates_scored"],
               "rmse_ned_m_s": d["wind_rmse_ned_m_s"], "rmse_horizontal_m_s": d["wind_rmse_horizontal_m_s"],
               "rmse_1s_ned_m_s": d["wind_rmse_1s_ned_m_s"], "rmse_1s_horizontal_m_s": d["wind_rmse_1s_horizontal_m_s"],
               "coverage_95_horizontal": d["wind_coverage_95_horizontal"]}  # fmt: skip
        s.extra[f"{ESTIMATE_LABEL} wind vs truth"] = _rmse_line(est)
        s.extra[f"{self.autopilot} wind vs truth"] = _rmse_line(d["autopilot_wind"])
        s.notes.append(f"Wind: {ESTIMATE_LABEL} (windseek's estimator, WIND_COV) orange in its ±2σ band, "
                       f"{self.autopilot} (the autopilot's own estimate) green, truth blue.")  # fmt: skip
        s.fill_from_phases(ph, rec.declaration is not None, self.bridge.t)
        self.tally.fill(s)
        return s

    def close(self) -> None:
        rec = self.rec
        d = self.score()
        kept = {k: v for k, v in d.items() if k != "wind_series_1s"}
        kept["autopilot_wind"] = {k: v for k, v in d["autopilot_wind"].items() if k != "series_1s"}
        self.meter(lambda: rec.property("truth_score", json=json.dumps(json_safe(kept), allow_nan=False)))
        self.meter(lambda: rec.summary(self.summary(d)))
        self.meter(rec.close, lambda: {"sim_s": round(self.bridge.t - self.t0, 3), **self.meter.report(rec)})


__all__ = ["ARDUCOPTER_LABEL", "ESTIMATE_LABEL", "PX4_LABEL", "AutopilotRecorder"]
