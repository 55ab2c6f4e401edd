"""Review of real flights: MAVLink telemetry logs (``.tlog``), PX4 ULogs (``.ulg``) and ArduPilot
DataFlash logs (``.bin``) to Rerun, with the wind estimator re-run offline.

- :mod:`review.detect`: which kind of log a file is, by content.
- :mod:`review.flight`: :class:`~review.flight.FlightData`, what a log holds in the project's
  conventions (SI, NED/FRD, wind = air-mass velocity NED), as columns.
- readers: :mod:`review.tlog` (with :mod:`review.tlog_scan`, :mod:`review.tlog_collect`,
  :mod:`review.tlog_columns`), :mod:`review.ulog` (:mod:`review.ulog_topics`), :mod:`review.dataflash`.
- :mod:`review.estimate`: the offline estimator re-run; :mod:`review.trust`: which of its samples
  are trusted and the figures; :mod:`review.summary`: the report; :mod:`review.rrd`: the recording.
- :mod:`review.convert`: :func:`~review.convert.review`, all of it; ``windseek review`` is its CLI.
"""

from review.convert import ReviewResult, read_flight, review
from review.summary import format_summary

__all__ = ["ReviewResult", "format_summary", "read_flight", "review"]
