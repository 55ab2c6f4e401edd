"""Run recordings for the Rerun viewer: a thin adapter over ``rerun-sdk``.

The simulator, estimator and strategies never import rerun; they hand SI/NED data to a
:class:`~recording.recorder.RunRecorder` (directly, or through
:func:`~recording.sim_hook.record_simulation` for the simulator's truth, or
:class:`~recording.trial.TrialRecorder` for an in-process trial). The modules:

- :mod:`recording.style`: timeline, colours, colour maps, plain-words state names;
- :mod:`recording.stream`: the recording stream and the buffered columns;
- :mod:`recording.scene`: the map (north up) and the 3D view;
- :mod:`recording.recorder`: time series, events, phases, summary, close;
- :mod:`recording.phases`: flight phases and their markers;
- :mod:`recording.ranges`, :mod:`recording.layout`: the plots' ranges and the viewer layout;
- :mod:`recording.summary`: the run summary the recording carries;
- :mod:`recording.finalize`: rewrite a finished recording with a new summary and the mission's own
  recording merged in (``windseek demo``);
- :mod:`recording.mission_rrd`: the mission's side (``windseek mission --rrd``: the strategy's posterior,
  the setpoints), listening to the mission loop;
- :mod:`recording.read`: read a saved ``.rrd`` back as numpy arrays;
- :mod:`recording.sim_hook`: the simulated world's truth (``record_world``; ``record_simulation``);
- :mod:`recording.wire_rx`: what arrives on a MAVLink link (estimates, mission, an autopilot's own);
- :mod:`recording.sitl_link`, :mod:`recording.autopilot_rrd`: ``windseek sitl --rrd`` with the built-in
  autopilot, and with PX4 or ArduPilot flying;
"""

from recording.recorder import RunRecorder
from recording.summary import RunSummary

__all__ = ["RunRecorder", "RunSummary"]
