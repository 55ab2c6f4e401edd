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
- :mod:`recording.finalize`: rewrite a finished recording with a new summary (``windseek demo``);
- :mod:`recording.read`: read a saved ``.rrd`` back as numpy arrays;
"""

from recording.recorder import RunRecorder
from recording.summary import RunSummary

__all__ = ["RunRecorder", "RunSummary"]
