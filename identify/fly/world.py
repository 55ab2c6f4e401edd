"""The identification manoeuvre flown in-process in windseek's world by the built-in autopilot.

The vehicle hovers (the scenario's airborne start), then flies the low-frequency reference in offboard
position + velocity + heading mode while the motor multisine is added to the controller's squared
rotor-speed commands inside the closed loop, as the paper injected its excitation at the motor
throttle commands (:meth:`sitl.autopilot.builtin.BuiltinAutopilot.set_excitation`).

What is recorded is what an autopilot would log: the IMU (accelerometer and gyroscope with their
noise, 250 Hz), the ESC rotor speeds (noisy, 50 Hz), the rotor-speed commands (its actuator outputs),
and the autopilot's velocity and attitude (the built-in autopilot navigates on the true state: its
stand-in for a navigation filter). The wind is
assumed zero (the ``calm`` scenario's mean); its turbulence is left for the fit to meet as error.
Samples where a motor command hit its limit (idle or maximum) are excluded with 0.1 s on each side.
"""

from __future__ import annotations

import math

import numpy as np

from identify.design import Manoeuvre, motor_excitation
from identify.flight_data import FlightData, runs, widen
from sitl.autopilot.flight_modes import Mode
from sitl.scenario import Scenario
from sitl.simulation import T_QUAT, T_ROTOR_CMD, T_TIME, T_VEL, Simulation
from vehicle.frames import quat_to_euler
from vehicle.params import VehicleParams


def fly(scenario: Scenario, seed: int, manoeuvre: Manoeuvre, vehicle: VehicleParams | None = None) -> FlightData:
    """Fly ``manoeuvre`` in ``scenario`` (it must start airborne) and return what was recorded."""
    if not scenario.start.airborne:
        raise ValueError(f"scenario {scenario.name}: the identification needs an airborne start ([start] airborne)")
    sim = Simulation(scenario.with_duration(manoeuvre.total_s + 1.0), seed=seed, vehicle=vehicle,
                     autostart_route=False, record_truth=True)  # fmt: skip
    v = sim.vehicle
    # The reference's descents may be faster than the autopilot's default limit (MPC_Z_VEL_MAX_DN 1.5 m/s):
    # the identified domain must hold the vertical airspeeds the estimator will meet (3 m/s updrafts).
    for gain in ("vel_max_down", "vel_max_up"):
        sim.set_gain(gain, max(sim.gain(gain), manoeuvre.spec.climb_m_s + 0.5))
    start = sim.position.copy()
    yaw0 = float(quat_to_euler(sim.quaternion)[2])
    tick0 = sim.tick
    t0 = sim.t
    ticks = np.arange(int(math.ceil(manoeuvre.total_s / sim.dt)) + 1)
    dw2 = motor_excitation(manoeuvre.virtual_at(ticks * sim.dt), v.mixing)
    sim.autopilot.set_excitation(dw2, tick0)

    def reference(s: Simulation) -> None:
        tm = s.t - t0
        vel, dyaw = manoeuvre.reference_at(tm)
        pos = start + manoeuvre.position_reference(tm)
        s.fc.offboard_setpoint(s.t, pos=pos, vel=vel, yaw=yaw0 + dyaw)

    reference(sim)
    ok, why = sim.fc.set_mode(Mode.OFFBOARD)
    if not ok:
        raise RuntimeError(f"identification flight: offboard refused ({why})")
    sim.step_hooks.append(reference)
    imu: list[tuple[float, np.ndarray, np.ndarray]] = []
    esc: list[tuple[float, np.ndarray]] = []
    n_steps = int(round(manoeuvre.total_s / sim.dt))
    chunk = int(round(1.0 / sim.dt))
    while sim.tick - tick0 < n_steps:
        sim.step(min(chunk, n_steps - (sim.tick - tick0)))
        out = sim.drain()
        imu += out["imu"]
        esc += out["esc"]
        if sim.crashed:
            raise RuntimeError(f"identification flight crashed at t = {sim.t:.1f} s (amplitudes too large?)")
    return _record(sim, v, imu, esc, t0, manoeuvre)


def _record(sim: Simulation, v: VehicleParams, imu: list[tuple[float, np.ndarray, np.ndarray]],
            esc: list[tuple[float, np.ndarray]], t0: float, manoeuvre: Manoeuvre) -> FlightData:  # fmt: skip
    truth = sim.truth_array()
    truth = truth[truth[:, T_TIME] >= t0 - 1e-9]
    t = np.array([s[0] for s in imu])
    keep = t >= t0 - 1e-9
    t = t[keep]
    acc = np.array([s[1] for s in imu])[keep]
    gyr = np.array([s[2] for s in imu])[keep]
    te = np.array([s[0] for s in esc])
    we = np.array([s[1] for s in esc])
    rotors = np.stack([np.interp(t, te, we[:, i]) for i in range(v.n_rotors)], axis=1)
    # truth rows are at the IMU instants: match them by time
    idx = np.clip(np.searchsorted(truth[:, T_TIME], t - 1e-9), 0, truth.shape[0] - 1)
    vel = truth[idx, T_VEL]
    quat = truth[idx, T_QUAT]
    cmd = truth[idx, T_ROTOR_CMD][:, : v.n_rotors]
    sat = np.any((cmd <= v.rotor_speed_min_rad_s + 1e-6) | (cmd >= v.rotor_speed_max_rad_s - 1e-6), axis=1)
    data = FlightData(t=t - t0, specific_force=acc, rates=gyr, rotor_speeds=rotors, velocity_ned=vel, quaternion=quat,
                      rotor_commands=cmd,
                      source=f"windseek world, scenario {sim.scenario.name}, seed {sim.seed}, truth {v.truth}, "
                      f"manoeuvre seed {manoeuvre.spec.seed}")  # fmt: skip
    if sat.any():
        bad = widen(sat, data.t, 0.1)
        spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in runs(bad, data.t)[:5])
        data = data.exclude(bad, f"motor command at its limit: {bad.mean() * 100:.1f} % of samples ({spans})")
    return data
