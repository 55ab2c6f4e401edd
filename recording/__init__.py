"""Run recordings for the Rerun viewer: a thin adapter over ``rerun-sdk``.

The simulator, estimator and strategies never import rerun; they hand SI/NED data to a
:class:`~recording.rerun_log.RunRecorder` (directly, or through
:func:`~recording.sim_hook.record_simulation` for the simulator's truth).
:mod:`recording.read` reads a saved ``.rrd`` back as numpy arrays.
"""

from recording.rerun_log import RunRecorder

__all__ = ["RunRecorder"]
