"""The built-in autopilot: a PX4-like flight controller that turns commands into rotor commands.

- ``flight_modes``: arming, take-off, hold, offboard, waypoint mission, land, return to launch
  (the mode logic, 50 Hz, plain Python), writing a setpoint vector;
- ``controller``: the cascaded position -> velocity -> attitude -> rate controller and the
  allocation through the inverse of the paper's Eq. 42 mixing (numba, every physics tick).

It is one source of rotor commands for the world; PX4 over HIL is another.
"""
