"""Peer measurement: how fast RotorPy steps a multirotor with its own controller.

Used by ``benchmarks/sim_speed.py`` to measure RotorPy (PyPI ``rotorpy`` 3.0.0)
in the same run and on the same machine as windseek. Importing this module has
no side effects; RotorPy itself is imported lazily inside the function.

Frame convention: RotorPy's world frame is z-up (ENU-style: x, y horizontal,
z up; gravity is ``[0, 0, -m g]`` in ``Multirotor``) and its body frame is
FLU-style (thrust along body +z). windseek uses NED, so a wind vector
``(north, east, down)`` maps to RotorPy as ``(x=east, y=north, z=-down)``.

Only RotorPy's constant wind is used: its Dryden wind needs torch, which is
deliberately not installed.
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import time

__all__ = ["rotorpy_realtime_factor", "ned_to_rotorpy_enu"]


def ned_to_rotorpy_enu(vec_ned):
    """Convert a NED vector (north, east, down) to RotorPy's ENU / z-up frame."""
    n, e, d = (float(c) for c in vec_ned)
    return (e, n, -d)


def rotorpy_realtime_factor(rate_hz: float, sim_seconds: float = 20.0,
                            wind_ned=(-10.0, 0.0, 0.0)) -> dict:
    """Simulated seconds per wall-clock second of RotorPy's Multirotor (its default quad
    params) with SE3Control on a hover trajectory in a constant wind, stepping at rate_hz, one core.

    Vehicle: ``rotorpy.vehicles.multirotor.Multirotor`` with the Crazyflie
    parameters (``rotorpy.vehicles.crazyflie_params.quad_params``), the set
    RotorPy's examples use (``examples/basic_usage.py`` and
    ``rotorpy/environments.py``), with Multirotor's defaults: motor-speed
    control abstraction, ``aero=True``, scipy ``solve_ivp`` RK45 per step.
    Controller: ``rotorpy.controllers.quadrotor_control.SE3Control``.
    Trajectory: ``rotorpy.trajectories.hover_traj.HoverTraj`` at the origin.
    Wind: ``rotorpy.wind.default_winds.ConstantWind`` built from ``wind_ned``
    converted to RotorPy's z-up frame (see module docstring).

    Each step reproduces the core of ``rotorpy.simulate.simulate``::

        t += dt
        state['wind'] = wind.update(t, state['x'])
        state = vehicle.step(state, control, dt)
        flat = trajectory.update(t)
        control = controller.update(t, state, flat)

    and leaves out simulate()'s bookkeeping that is not part of stepping the
    vehicle with its controller (history lists, safety/exit checks, the mocap,
    IMU and estimator calls, the extra ``statedot`` for the IMU).

    Only the stepping loop is timed (construction and imports are not). The
    process is pinned to one CPU during the loop when the OS allows it and the
    previous affinity is restored afterwards.

    Returns a dict with ``rate_hz``, ``sim_seconds`` (simulated time actually
    stepped), ``wall_s``, ``realtime_factor`` (sim_seconds / wall_s) and
    ``final_position_error_m`` (distance from the hover point at the end; NaN
    or inf if the state did not stay finite).
    """
    import numpy as np
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.trajectories.hover_traj import HoverTraj
    from rotorpy.vehicles.crazyflie_params import quad_params as _cf_params
    from rotorpy.vehicles.multirotor import Multirotor
    from rotorpy.wind.default_winds import ConstantWind

    rate_hz = float(rate_hz)
    if not rate_hz > 0:
        raise ValueError("rate_hz must be positive")
    dt = 1.0 / rate_hz
    n_steps = max(1, int(round(float(sim_seconds) * rate_hz)))

    params = copy.deepcopy(_cf_params)
    hover_point = np.zeros(3)
    hover_speed = math.sqrt(params["mass"] * 9.81 / (params["num_rotors"] * params["k_eta"]))
    initial_state = {
        "x": hover_point.copy(),
        "v": np.zeros(3),
        "q": np.array([0.0, 0.0, 0.0, 1.0]),  # [i, j, k, w]
        "w": np.zeros(3),
        "wind": np.zeros(3),  # overwritten by the wind profile each step
        "rotor_speeds": np.full(params["num_rotors"], hover_speed),
    }

    vehicle = Multirotor(params, initial_state=copy.deepcopy(initial_state))
    controller = SE3Control(params)
    trajectory = HoverTraj(x0=hover_point.copy())
    wind = ConstantWind(*ned_to_rotorpy_enu(wind_ned))

    # Initial conditions, as simulate() sets them up.
    t = 0.0
    state = {k: np.array(v, dtype=float) for k, v in initial_state.items()}
    state["wind"] = wind.update(t, state["x"])
    flat = trajectory.update(t)
    control = controller.update(t, state, flat)

    old_affinity = None
    if hasattr(os, "sched_getaffinity") and hasattr(os, "sched_setaffinity"):
        try:
            old_affinity = os.sched_getaffinity(0)
            os.sched_setaffinity(0, {min(old_affinity)})
        except OSError:
            old_affinity = None
    try:
        t0 = time.perf_counter()
        for i in range(1, n_steps + 1):
            t = i * dt
            state["wind"] = wind.update(t, state["x"])
            state = vehicle.step(state, control, dt)
            flat = trajectory.update(t)
            control = controller.update(t, state, flat)
        wall_s = time.perf_counter() - t0
    finally:
        if old_affinity is not None:
            with contextlib.suppress(OSError):
                os.sched_setaffinity(0, old_affinity)

    sim_s = n_steps * dt
    final_err = float(np.linalg.norm(np.asarray(state["x"], dtype=float) - hover_point))
    return {
        "rate_hz": rate_hz,
        "sim_seconds": sim_s,
        "wall_s": wall_s,
        "realtime_factor": sim_s / wall_s if wall_s > 0 else float("inf"),
        "final_position_error_m": final_err,
    }
