"""Review of real flights: MAVLink telemetry logs (``.tlog``) and PX4 ULogs (``.ulg``) to Rerun.

- :mod:`review.flight`: :class:`~review.flight.FlightData`, what a log holds in the project's
  conventions (SI, NED/FRD, wind = air-mass velocity NED).
- :mod:`review.tlog`, :mod:`review.ulog`: the readers.
- :mod:`review.convert`: :func:`~review.convert.review` re-runs the wind estimator offline on the
  recorded sensors and writes a ``.rrd`` with the live runs' layout; ``windseek review`` is its CLI.
"""

from review.convert import ReviewResult, format_summary, read_flight, review

__all__ = ["ReviewResult", "format_summary", "read_flight", "review"]
