"""Source-seeking missions on the estimated wind (issue 6).

- ``strategies``: anemotaxis, surge-cast, zig-zag: plain, synchronous, deterministic state
  machines (observation in, setpoint out), parameters validated from a strategy file.
- ``runners``: in-process lockstep (batch evaluation) and MAVSDK (real time, SITL or a real
  autopilot); they hold no strategy logic.
- ``wind_source``: the wind the strategy sees (estimated, oracle or none).
- ``safety``: geofence, altitude limits, time limit, hold-then-land on faults.
- ``evaluate``: seeded batches in parallel processes and their summary.

Conventions: SI units, NED world frame, wind = air-mass velocity in NED.
"""
