"""Record a lockstep :class:`~sitl.simulation.Simulation`'s truth through a :class:`RunRecorder`.

:func:`record_simulation` appends a ``sim.step_hooks`` entry, called at every mode tick
(``physics.mode_rate_hz``, 50 Hz by default) with the simulation, and logs at the
recommended rates (each rounded to a whole number of mode ticks):

    vehicle pose + trail, true wind arrow   vehicle_hz (25 Hz)
    true wind per axis, speed, from-dir     series_hz (25 Hz)
    rotor speeds (truth, rad/s)             series_hz
    chemical reading (sim.chem.latest)      every new reading (the sensor's own rate)
    plume slice at flight altitude          slice_hz (0.5 Hz)
    puffs                                   puffs_hz (2 Hz)
    flight mode / arming / crash changes    on change, as text at ``log/events``

and once, at attach time: the true sources and, when the plume has a domain box, the
geofence. The plume hook is registered by ``Simulation.__init__`` before this one, so the
chemical reading and plume state logged at a tick are those of that same tick.

Estimator and strategy data are logged by their runners through the recorder's methods
(``wind(est_ned=...)``, ``wind_speed_dir``, ``chem(threshold)``, ``sources(declared)``,
``text``), on the same ``sim_time`` timeline.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from recording.rerun_log import RunRecorder
from vehicle.frames import from_direction_deg

if TYPE_CHECKING:
    from sitl.simulation import Simulation

#: Default margin of the plume slice around the sources and the start point [m].
SLICE_MARGIN_M = 30.0


def wind_speed_from_deg(wind_ned: np.ndarray) -> tuple[float, float]:
    """Horizontal speed [m/s] and meteorological from-direction [deg, 0 = from north, 90 = from
    east, in [0, 360)] of an air-mass velocity [m/s, NED]."""
    n, e = float(wind_ned[0]), float(wind_ned[1])
    return math.hypot(n, e), float(from_direction_deg(n, e))


def _every(mode_rate_hz: float, rate_hz: float) -> int:
    """Mode ticks between two logs for a wanted rate (>= 1; 0 Hz disables: returns 0)."""
    if rate_hz <= 0.0:
        return 0
    return max(1, round(mode_rate_hz / rate_hz))


def _slice_bounds(sim: Simulation, margin_m: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """North and east ranges [m] covering the plume sources and the start point, plus a margin."""
    pts = [np.asarray(sim.scenario.start.position_ned, dtype=float)[:2]]
    plume = sim.plume
    if plume is not None:
        pts += [np.asarray(s.position_ned, dtype=float)[:2] for s in plume.config.sources]
    arr = np.array(pts)
    lo, hi = arr.min(axis=0) - margin_m, arr.max(axis=0) + margin_m
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


def record_simulation(
    sim: Simulation,
    recorder: RunRecorder,
    *,
    vehicle_hz: float = 25.0,
    series_hz: float = 25.0,
    slice_hz: float = 0.5,
    puffs_hz: float = 2.0,
    slice_resolution_m: float = 2.0,
    slice_bounds_ned: tuple[tuple[float, float], tuple[float, float]] | None = None,
) -> Callable[[Simulation], None]:
    """Log ``sim``'s truth to ``recorder`` from now on (see the module docstring for rates).

    Args:
        sim: the simulation (a ``[plume]`` scenario adds chemical readings, slice and puffs).
        recorder: where to log.
        vehicle_hz, series_hz, slice_hz, puffs_hz: wanted rates [Hz]; 0 disables that part.
        slice_resolution_m: grid spacing of the plume slice [m].
        slice_bounds_ned: ((n_min, n_max), (e_min, e_max)) of the slice [m]; default: the
            sources and the start point with a ``SLICE_MARGIN_M`` margin.

    Returns the hook (already appended to ``sim.step_hooks``; remove it to stop recording).
    """
    mode_rate = sim.scenario.mode_rate_hz
    n_vehicle = _every(mode_rate, vehicle_hz)
    n_series = _every(mode_rate, series_hz)
    n_slice = _every(mode_rate, slice_hz)
    n_puffs = _every(mode_rate, puffs_hz)
    plume = sim.plume
    if plume is not None:
        recorder.sources([s.position_ned for s in plume.config.sources])
        if plume.config.domain_min_ned is not None and plume.config.domain_max_ned is not None:
            recorder.geofence(plume.config.domain_min_ned, plume.config.domain_max_ned)
    xr, yr = slice_bounds_ned or _slice_bounds(sim, SLICE_MARGIN_M)
    xs = np.linspace(xr[0], xr[1], max(2, round((xr[1] - xr[0]) / slice_resolution_m) + 1))
    ys = np.linspace(yr[0], yr[1], max(2, round((yr[1] - yr[0]) / slice_resolution_m) + 1))
    grid_xy = np.column_stack([g.ravel() for g in np.meshgrid(xs, ys, indexing="ij")])
    takeoff_z = -float(sim.scenario.route.takeoff_altitude_m)
    last: dict[str, object] = {"mode": None, "armed": None, "crashed": False, "chem_t": None}

    def hook(s: Simulation) -> None:
        k = s.tick // s.world.slow_div
        t = s.t
        pos = s.x[0:3]
        wind: np.ndarray | None = None
        if n_vehicle and k % n_vehicle == 0:
            wind = s.wind_at_vehicle
            recorder.vehicle(t, pos, s.x[6:10])
            recorder.wind_arrows(t, pos, wind)
        if n_series and k % n_series == 0:
            if wind is None:
                wind = s.wind_at_vehicle
            recorder.wind(t, truth_ned=wind)
            speed, from_deg = wind_speed_from_deg(wind)
            recorder.wind_speed_dir(t, None, None, truth_speed=speed, truth_dir_deg=from_deg)
            recorder.rotors(t, s.x[13:17])
        reading = s.chem.latest if s.chem is not None else None
        if reading is not None and reading.t != last["chem_t"]:
            last["chem_t"] = reading.t
            recorder.chem(reading.t, reading.value_mg_m3)
        pl = s.plume
        if pl is not None:
            if n_slice and k % n_slice == 0:
                # The slice is at the flight altitude: the vehicle's, or the take-off
                # altitude while it is still on the ground.
                z = float(pos[2]) if pos[2] < -0.5 else takeoff_z
                pts = np.column_stack([grid_xy, np.full(len(grid_xy), z)])
                conc = np.asarray(pl.concentration(pts)).reshape(len(xs), len(ys))
                recorder.plume_slice(t, xs, ys, conc, z)
            puffs = s.chem.puff_array() if s.chem is not None else None
            if n_puffs and k % n_puffs == 0 and puffs is not None:
                recorder.puffs(t, puffs)
        fc = s.fc
        if fc.mode != last["mode"]:
            recorder.text(t, f"mode {getattr(fc.mode, 'name', fc.mode)}", "INFO")
            last["mode"] = fc.mode
        if fc.armed != last["armed"]:
            recorder.text(t, "armed" if fc.armed else "disarmed", "INFO")
            last["armed"] = fc.armed
        if s.crashed and not last["crashed"]:
            recorder.text(t, "crash: touchdown too fast", "ERROR")
            last["crashed"] = True

    sim.step_hooks.append(hook)
    return hook


__all__ = ["SLICE_MARGIN_M", "record_simulation", "wind_speed_from_deg"]
