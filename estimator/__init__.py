"""The paper's wind estimator (Eq. 49-53): an unscented Kalman filter on the rotor force model.

Plain, synchronous, deterministic code; the adapters feed it. One job per module:

- ``ukf``: the filter (:class:`~estimator.ukf.WindEstimator`), built on filterpy's UKF.
- ``config``: its tuning (:class:`~estimator.config.EstimatorConfig`) and the two presets.
- ``model_kernels``: the force model, process step and accelerometer model (numba).
- ``gating``: input checks (non-finite, out of range, out of order), counted by reason.
- ``outputs``: :class:`~estimator.outputs.WindEstimate` and the read-only views of the state.
- ``direction``: speed and from-direction with uncertainty; the Butterworth direction filter.
- ``ground_gate``: when to feed the filter around the ground (pause, restart at lift-off).
- ``inprocess``: the simulator's sensor outputs in lockstep (batch evaluation).
- ``mavlink_adapter``: pymavlink messages in, WIND_COV out (SITL or a real autopilot).
- ``rpm_free``: rotor speeds implied by the motor commands when there is no ESC telemetry.
- ``metrics``: accuracy figures against the simulator's truth.

Conventions: SI units, NED world frame, FRD body frame, wind = air-mass velocity in NED.
"""
