"""What a flight log must hold for the identification, said in one line: :func:`problems`.

A log is refused when its vehicle is not a multirotor (a wing's lift and drag are not in Eq. 46), when
the vehicle file's rotor count is not the four rotors the log readers decode, or when it lacks an IMU
(accelerometer and gyroscope, fast enough), attitude, a 3-D velocity, rotor speeds or actuator outputs,
or an airborne segment. Every problem found is named, not just the first.
"""

from __future__ import annotations

from review.flight import FlightData, Series
from vehicle.params import VehicleParams

#: Vehicle types (review.vehicle_info words) that are multirotors, or may be ("unknown": the log does not say).
MULTIROTOR_WORDS = ("quadrotor", "hexarotor", "octorotor", "multicopter", "tricopter", "coaxial", "octa-quad",
                    "y6", "decarotor", "dodecarotor", "unknown")  # fmt: skip
#: Rotors per log row: the review's readers decode ESC / outputs 1-4.
LOG_ROTORS = 4


def problems(log: FlightData, vehicle: VehicleParams, velocity: Series, outputs: Series,
             min_imu_hz: float) -> list[str]:  # fmt: skip
    """Everything that keeps the log from being identified (empty: nothing). ``velocity``: the log's
    velocity rows with all three components finite; ``outputs``: its actuator outputs (maybe empty)."""
    found = []
    kind = log.vehicle_type.lower()
    if not any(w in kind for w in MULTIROTOR_WORDS) or "vtol" in kind:
        found.append(f"the log's vehicle is a {log.vehicle_type} ({log.autopilot}), not a multirotor: Eq. 46 "
                     "models rotor forces only")  # fmt: skip
    if vehicle.n_rotors != LOG_ROTORS:
        found.append(f"vehicle {vehicle.name} has {vehicle.n_rotors} rotors; the log readers decode {LOG_ROTORS}")
    if not len(log.imu):
        found.append("no IMU (accelerometer and gyroscope)")
    elif not (log.imu.v[:, 3:6] == log.imu.v[:, 3:6]).any():
        found.append(f"no gyroscope in the IMU ({log.sources.get('imu')})")
    elif log.imu.rate_hz < min_imu_hz:
        found.append(f"IMU at {log.imu.rate_hz:.1f} Hz ({log.sources.get('imu')}): at least {min_imu_hz:g} Hz is "
                     "needed (the moments come from the gyroscope's derivative)")  # fmt: skip
    if not len(log.attitude):
        found.append("no attitude")
    if not len(velocity):
        found.append("no 3-D velocity" + (f" ({log.sources['velocity']} gives none with the down component)"
                                           if len(log.velocity) else ""))  # fmt: skip
    if not len(log.rotors) and not len(outputs):
        found.append("no rotor speeds (ESC telemetry) and no actuator outputs")
    if not log.airborne_segments():
        why = f" ({log.sources['in_air']})" if "in_air" in log.sources else " (neither a landed state nor arming)"
        found.append("no airborne segment" + why)
    return found
