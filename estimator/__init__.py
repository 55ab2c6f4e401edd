"""The paper's wind estimator (Eq. 49-53): an unscented Kalman filter on the rotor force model.

Plain, synchronous, deterministic code; the adapters feed it. One job per module (see README.md):

- ``ukf``: the filter (:class:`~estimator.ukf.WindEstimator`); ``config``: its tuning and presets;
  ``model_kernels``: the force model; ``sigma_kernels`` / ``step_kernels``: the unscented
  arithmetic (numba); ``gating``: input checks; ``outputs``: the estimate; ``direction``: speed
  and from-direction, the Butterworth direction filter; ``reference``: filterpy's UKF on the same
  model (the yardstick of tests and benchmarks).
- ``live``: the live core on a MAVLink stream (lock-on, inputs, ground gate, clock resets);
  ``live_select``, ``mavlink_decode``, ``motor_output``, ``rpm_free``, ``ground_gate``: its parts;
  ``worker``: the live core in a thread for asyncio programs.
- ``inprocess``: the simulator's sensor outputs in lockstep; ``mavlink_adapter``: log replay and
  WIND_COV; ``metrics``: accuracy figures against the simulator's truth.

Conventions: SI units, NED world frame, FRD body frame, wind = air-mass velocity in NED.
"""
