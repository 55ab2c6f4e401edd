"""The vehicle model shared by the simulated world and the wind estimator.

- ``params``: :class:`VehicleParams` and :func:`load_vehicle`: every vehicle parameter, one
  TOML file per vehicle (``vehicles/nasa_quad.toml``, the paper's quadrotor).
- ``rotor_model``: the paper's identified rotor force and moment model (Eq. 40-46), numba.
- ``frames``: quaternions, rotations and Euler angles (NED world, FRD body).

The world flies this model; the estimator inverts it. Neither imports the other.
"""
