"""Former home of the recorder, kept so older imports keep working: see :mod:`recording.recorder`."""

from recording.layout import make_blueprint
from recording.recorder import RunRecorder
from recording.style import AXES, TEXT_LEVELS, TIMELINE, log_colormap

__all__ = ["AXES", "TEXT_LEVELS", "TIMELINE", "RunRecorder", "log_colormap", "make_blueprint"]
