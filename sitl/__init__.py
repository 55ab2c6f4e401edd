"""windseek SITL: a lightweight multirotor simulator after the paper's identified quadrotor.

Conventions used everywhere in this project:

- SI units (m, s, kg, rad, N, N*m); rotor speeds in rad/s.
- World frame NED (x north, y east, z down); the origin is the start point on the ground.
- Body frame FRD (x forward, y right, z down).
- Wind is the *air-mass velocity* expressed in NED: the velocity the air moves with.
  A 10 m/s wind *from* the north blows toward the south: [-10, 0, 0] m/s NED.
- Airspeed (vehicle velocity relative to the air) = ground velocity - wind.
- Documentation gives angles in degrees and the wind direction as the from-direction
  (meteorological convention, 0 = from north, 90 = from east).

Layout: ``world/`` (what a vehicle experiences: dynamics, wind, plume, sensors), ``autopilot/``
(the built-in PX4-like autopilot), ``link/`` (the MAVLink endpoint), ``scenario.py``,
``simulation.py`` (world + built-in autopilot in lockstep). Numba caches its kernels where
:func:`toolchain.numba_cache.configure` says (the entry points call it).
"""
