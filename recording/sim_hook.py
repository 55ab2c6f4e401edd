"""Record a simulated world's truth through a :class:`RunRecorder`: the built-in SITL's or an autopilot's.

:func:`record_world` makes the hook, called at every mode tick (``physics.mode_rate_hz``, 50 Hz by
default) with a :class:`WorldSource` (anything with a ``world`` and its ``scenario``: a
:class:`~sitl.simulation.Simulation`, or the bridge of PX4's or ArduPilot's simulator, which call
their ``step_hooks`` at their truth samples), and logs at these rates (each rounded to a whole
number of mode ticks):

    vehicle pose + path, true wind arrow    vehicle_hz (25 Hz)
    true wind per axis, speed, from-dir     series_hz (25 Hz)
    rotor speeds (truth, rad/s)             series_hz
    altitude (truth, m up above the start)  series_hz
    chemical reading (sim.chem.latest)      every new reading (the sensor's own rate)
    plume at flight altitude (map, 3D)      slice_hz (0.5 Hz)
    plume on the vertical plane along the   slice_hz
      wind through the source (3D)
    puff centres                            puffs_hz (0: off; the field above shows the plume)
    flight mode, arming, crash              on change (phases, events log)

Arming, flight mode and crash come from ``status(source)``: the built-in autopilot's
(:func:`record_simulation`, which also registers the hook on ``sim.step_hooks``), or, with PX4 or
ArduPilot flying, the arming their outputs say and no mode (the listener of their MAVLink messages
logs the mode from their HEARTBEAT).

And once, at attach time: the true sources, the scene (start and sources, the take-off altitude),
the detection threshold and, in an urban scenario (``[urban]`` buildings), the buildings and the
mean wind field at flight altitude and on the vertical plane along the wind through the source
(:func:`record_urban`, :mod:`recording.urban_scene`). The plume hook is registered by
``Simulation.__init__`` before this one, so the chemical reading and plume state logged at a tick
are those of that same tick.

Estimator and strategy data are logged by their runners through the recorder's methods
(``wind(est_ned=...)``, ``wind_speed_dir``, ``strategy_state``, ``declare``, ``summary``), on the
same timeline (vehicle time = simulation time).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from recording.recorder import RunRecorder

if TYPE_CHECKING:
    from sitl.scenario import Scenario
    from sitl.simulation import Simulation
    from sitl.world.world import World


class WorldSource(Protocol):
    """What the truth is read from: the world and the scenario it was built from (a ``Simulation``, a
    ``HilBridge``, an ``ArduPilotBridge``)."""

    @property
    def world(self) -> World: ...

    @property
    def scenario(self) -> Scenario: ...


#: ``status(source)`` -> (flight mode or None when not known here, armed).
Status = Callable[[Any], tuple[object, bool]]

#: Default margin of the plume slice around the sources and the start point [m].
SLICE_MARGIN_M = 30.0
#: Margin of the urban wind field's slice around the map's extent at attach time [m] (the path may
#: widen the map later).
FIELD_MARGIN_M = 20.0


def wind_speed_from_deg(wind_ned: np.ndarray) -> tuple[float, float]:
    """Horizontal speed [m/s] and meteorological from-direction [deg, 0 = from north, 90 = from
    east, in [0, 360)] of an air-mass velocity [m/s, NED]."""
    n, e = float(wind_ned[0]), float(wind_ned[1])
    # math, not vehicle.frames.from_direction_deg: the same formula without numpy's per-call cost
    return math.hypot(n, e), math.degrees(math.atan2(-e, -n)) % 360.0


def _every(mode_rate_hz: float, rate_hz: float) -> int:
    """Mode ticks between two logs for a wanted rate (>= 1; 0 Hz disables: returns 0)."""
    if rate_hz <= 0.0:
        return 0
    return max(1, round(mode_rate_hz / rate_hz))


def _slice_bounds(src: WorldSource, margin_m: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """North and east ranges [m] covering the plume sources and the start point, plus a margin."""
    pts = [np.asarray(src.scenario.start.position_ned, dtype=float)[:2]]
    chem = src.world.plume
    if chem is not None:
        pts += [p[:2] for p in chem.sources_ned]
    arr = np.array(pts)
    lo, hi = arr.min(axis=0) - margin_m, arr.max(axis=0) + margin_m
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


class _Curtain:
    """The vertical plane along the mean wind through the (first) source: s from 10 m upwind to the
    start's distance plus a margin, z from the ground up to three flight altitudes."""

    def __init__(self, ws: WorldSource, resolution_m: float, altitude_m: float) -> None:
        chem, wind = ws.world.plume, ws.world.wind
        src = chem.sources_ned[0] if chem is not None else np.zeros(3)
        start = np.asarray(ws.scenario.start.position_ned, dtype=float)
        reach = float(np.hypot(*(start[:2] - src[:2]))) + SLICE_MARGIN_M
        self.origin = src[:2].copy()
        self.s = np.arange(-10.0, reach + 1e-9, resolution_m)
        self.z = -np.arange(0.0, max(3.0 * altitude_m, 12.0) + 1e-9, 0.5 * resolution_m)
        self.src_z = float(src[2])
        # Buildings (an urban wind field's exact prisms): no plume drawn inside them.
        self.inside: Callable[[np.ndarray], np.ndarray] | None = getattr(getattr(wind, "field", None), "inside",
                                                                          None)  # fmt: skip

    def points(self, world: World) -> tuple[np.ndarray, np.ndarray]:
        """Downwind unit vector (north, east) of the mean wind at the source now, and the (S*Z, 3) points."""
        w = world.wind.mean(world.t, np.array([self.origin[0], self.origin[1], self.src_z]))
        h = float(np.hypot(w[0], w[1]))
        d = np.array([w[0], w[1]]) / h if h > 1e-6 else np.array([-1.0, 0.0])
        ss, zz = np.meshgrid(self.s, self.z, indexing="ij")
        pts = np.column_stack([self.origin[0] + ss.ravel() * d[0], self.origin[1] + ss.ravel() * d[1], zz.ravel()])
        return d, pts


def _section_plane(ws: WorldSource, field: Any, res_m: float, altitude_m: float,
                   top_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Origin (the first source, else the start), downwind unit vector (north, east) of the mean wind
    at the source (the plume's curtain's plane, :class:`_Curtain`; the upstream wind where it is
    calm), s [m] from 25 m upwind to 25 m past the start's along-wind distance, heights [m]."""
    start = np.asarray(ws.scenario.start.position_ned, dtype=float)[:2]
    chem, world = ws.world.plume, ws.world
    src = chem.sources_ned[0] if chem is not None else np.array([*start, -altitude_m])
    origin = np.array(src[:2], dtype=float)
    w = np.asarray(world.wind.mean(world.t, np.asarray(src, dtype=float)), dtype=float)[:2]
    up = np.asarray(field.scene.wind.direction_ned, dtype=float)
    u = w / float(np.hypot(*w)) if float(np.hypot(*w)) > 1e-6 else up
    reach = max(float((start - origin) @ u), 0.0) + 25.0
    s = np.arange(-25.0, reach + 1e-9, res_m)
    h = np.arange(0.0, max(top_m, 3.0 * altitude_m, 12.0) + 1e-9, min(1.0, res_m))
    return origin, u, s, h


def record_urban(sim: WorldSource, recorder: RunRecorder, altitude_m: float) -> bool:
    """Log a scenario's buildings and its mean urban wind field (static: the mean field is steady):
    the horizontal slice at ``altitude_m`` [m above the ground] over the map's extent (plus
    ``FIELD_MARGIN_M``) and the vertical section along the wind through the source. False (nothing
    logged) in an open field."""
    urban = getattr(sim.scenario, "urban", None)
    if urban is None or not urban.buildings:
        return False
    bs = list(urban.buildings)
    recorder.buildings([b.footprint() for b in bs], [b.height_m for b in bs], [getattr(b, "name", "") for b in bs])
    field = getattr(sim.world.wind, "field", None)  # sitl.world.urban.UrbanWindField: mean(), inside(), scene
    if field is None:
        return True
    n0, n1, e0, e1 = recorder.scene_bounds()
    n0, n1, e0, e1 = n0 - FIELD_MARGIN_M, n1 + FIELD_MARGIN_M, e0 - FIELD_MARGIN_M, e1 + FIELD_MARGIN_M
    res = max(float(field.scene.grid.spacing_m), max(n1 - n0, e1 - e0) / 200.0)
    xs, ys = np.arange(n0, n1 + 1e-9, res), np.arange(e0, e1 + 1e-9, res)
    nn, ee = np.meshgrid(xs, ys, indexing="ij")
    pts = np.column_stack([nn.ravel(), ee.ravel(), np.full(nn.size, -altitude_m)])
    w = np.array(field.mean(pts), dtype=float)
    w[np.asarray(field.inside(pts), dtype=bool)] = np.nan
    recorder.wind_field_slice(xs, ys, w[:, :2].reshape(len(xs), len(ys), 2), altitude_m)
    origin, u, s, h = _section_plane(sim, field, res, altitude_m, 1.5 * max(b.height_m for b in bs))
    ss, hh = np.meshgrid(s, h, indexing="ij")
    pts = np.column_stack([origin[0] + ss.ravel() * u[0], origin[1] + ss.ravel() * u[1], -hh.ravel()])
    w = np.array(field.mean(pts), dtype=float)
    w[np.asarray(field.inside(pts), dtype=bool)] = np.nan
    along = (w[:, :2] @ u).reshape(len(s), len(h))
    recorder.wind_field_section(origin, u, s, h, along, w[:, 2].reshape(len(s), len(h)))
    return True


class _TruthHook:
    """The hook :func:`record_world` returns: what is due at a mode tick (see the module docstring)."""

    def __init__(self, ws: WorldSource, recorder: RunRecorder, status: Status,
                 rates_hz: tuple[float, float, float, float], slice_resolution_m: float,
                 slice_bounds_ned: tuple[tuple[float, float], tuple[float, float]] | None,
                 field_altitude_m: float | None, meter: Callable[..., object] | None) -> None:  # fmt: skip
        sc, world = ws.scenario, ws.world
        mode_rate = sc.mode_rate_hz
        self.rec, self.status, self.meter = recorder, status, meter
        self.n_vehicle, self.n_series, self.n_slice, self.n_puffs = (_every(mode_rate, r) for r in rates_hz)
        self.takeoff_z = -float(sc.route.takeoff_altitude_m)
        self.start = np.asarray(sc.start.position_ned, dtype=float)
        chem = world.plume
        sources = [] if chem is None else chem.sources_ned.tolist()
        recorder.set_scene([self.start[:2], *(s[:2] for s in sources)], altitude_m=-self.takeoff_z)
        if chem is not None:
            recorder.sources(sources)
            recorder.set_chem_threshold(chem.sensor.config.detection_limit_mg_m3)
        record_urban(ws, recorder, -self.takeoff_z if field_altitude_m is None else float(field_altitude_m))
        xr, yr = slice_bounds_ned or _slice_bounds(ws, SLICE_MARGIN_M)
        self.xs = np.linspace(xr[0], xr[1], max(2, round((xr[1] - xr[0]) / slice_resolution_m) + 1))
        self.ys = np.linspace(yr[0], yr[1], max(2, round((yr[1] - yr[0]) / slice_resolution_m) + 1))
        self.grid_xy = np.column_stack([g.ravel() for g in np.meshgrid(self.xs, self.ys, indexing="ij")])
        self.curtain = _Curtain(ws, slice_resolution_m, -self.takeoff_z) if chem is not None else None
        self.last: dict[str, object] = {"crashed": False, "chem_t": None, "mode": None, "armed": None}
        # Mode ticks on which something is due (the sensor samples on its own multiple of the mode ticks).
        n_chem = _every(mode_rate, chem.setup.sensor.sample_rate_hz) if chem is not None else 0
        periods = [n for n in (self.n_vehicle, self.n_series, self.n_slice, self.n_puffs, n_chem) if n]
        self.step = math.gcd(*periods) if periods else 1  # nothing is due on the ticks between its multiples

    def _run(self, fn: Callable[..., None], *args: object) -> None:
        if self.meter is None:
            fn(*args)
        else:
            self.meter(fn, *args)

    def __call__(self, ws: WorldSource) -> None:
        w = ws.world
        mode, armed = self.status(ws)
        last = self.last
        # Mode and arming first: the path points of this tick then carry the new phase.
        if mode is not last["mode"] or armed != last["armed"] or (w.crashed and not last["crashed"]):
            self._run(self.changed, w, mode, armed)
        k = w.tick // w.slow_div
        if not k % self.step:  # the hook runs at every mode tick: most have nothing due
            self._run(self.due, w, k)

    def changed(self, w: World, mode: object, armed: bool) -> None:
        t, last, rec = w.t, self.last, self.rec
        if mode is not last["mode"]:
            last["mode"] = mode
            if mode is not None:
                rec.flight_mode(t, str(getattr(mode, "value", mode)))
        if armed != last["armed"]:
            last["armed"] = armed
            rec.armed(t, bool(armed))
        if w.crashed and not last["crashed"]:
            rec.text(t, "crash: touchdown too fast", "ERROR")
            last["crashed"] = True

    def due(self, w: World, k: int) -> None:
        t, rec = w.t, self.rec
        pos = w.x[0:3]
        # The wind the physics used at its newest IMU instant (<= 1 IMU period before t), at that
        # instant's own time: no second sample of the field (~10 us) per row.
        t_wind, wind = w.last_wind
        if self.n_vehicle and k % self.n_vehicle == 0:
            rec.vehicle(t, pos, w.x[6:10])
            rec.wind_arrows(t, pos, wind)
        if self.n_series and k % self.n_series == 0:
            rec.wind(t_wind, truth_ned=wind)
            speed, from_deg = wind_speed_from_deg(wind)
            rec.wind_speed_dir(t_wind, None, None, truth_speed=speed, truth_dir_deg=from_deg)
            rec.rotors(t, w.x[13:17])
            rec.altitude(t, float(self.start[2] - pos[2]))  # up, above the start point
        chem = w.plume
        reading = chem.latest if chem is not None else None
        if reading is not None and reading.t != self.last["chem_t"]:
            self.last["chem_t"] = reading.t
            rec.chem(reading.t, reading.value_mg_m3)
        if chem is not None:
            if self.n_slice and k % self.n_slice == 0:
                self.plume(w, chem.model, t, pos)
            if self.n_puffs and k % self.n_puffs == 0 and (puffs := chem.puff_array()) is not None:
                rec.puffs(t, puffs)

    def plume(self, w: World, pl: Any, t: float, pos: np.ndarray) -> None:
        """The plume at the flight altitude (the vehicle's, or the take-off altitude while on the
        ground) and on the curtain along the wind through the source."""
        xs, ys = self.xs, self.ys
        z = float(pos[2]) if pos[2] < -0.5 else self.takeoff_z
        pts = np.column_stack([self.grid_xy, np.full(len(self.grid_xy), z)])
        conc = np.asarray(pl.concentration(pts)).reshape(len(xs), len(ys))
        self.rec.plume_slice(t, xs, ys, conc, z)
        cur = self.curtain
        if cur is not None:
            d, cpts = cur.points(w)
            cc = np.asarray(pl.concentration(cpts)).reshape(len(cur.s), len(cur.z))
            if cur.inside is not None:
                cc = np.where(np.asarray(cur.inside(cpts)).reshape(cc.shape), 0.0, cc)
            self.rec.plume_curtain(t, cur.origin, d, cur.s, cur.z, cc)


def record_world(
    ws: WorldSource,
    recorder: RunRecorder,
    *,
    status: Status,
    vehicle_hz: float = 25.0,
    series_hz: float = 25.0,
    slice_hz: float = 0.5,
    puffs_hz: float = 0.0,
    slice_resolution_m: float = 2.0,
    slice_bounds_ned: tuple[tuple[float, float], tuple[float, float]] | None = None,
    field_altitude_m: float | None = None,
    meter: Callable[..., object] | None = None,
) -> Callable[[Any], None]:
    """Log ``ws``'s truth to ``recorder`` from now on (see the module docstring for rates); the static
    parts now, the rest by the returned hook, which the caller runs at every mode tick with ``ws``.

    Args:
        ws: the world and its scenario (a ``[plume]`` scenario adds chemical readings and the plume).
        recorder: where to log.
        status: ``status(ws)`` -> (flight mode or None, armed), asked at every mode tick.
        vehicle_hz, series_hz, slice_hz, puffs_hz: wanted rates [Hz]; 0 disables that part.
        slice_resolution_m: grid spacing of the plume slices [m].
        slice_bounds_ned: ((n_min, n_max), (e_min, e_max)) of the horizontal slice [m]; default: the
            sources and the start point with a ``SLICE_MARGIN_M`` margin.
        field_altitude_m: height of the urban wind field's horizontal slice [m above the ground]
            (default: the take-off altitude).
        meter: ``meter(fn, ...)`` runs the logging of a tick that has something due and counts its
            CPU time (``recording.stream.CpuMeter``). Only those ticks: the per-tick check before
            them costs about a microsecond, a meter call (two thread-CPU clock reads) five.
    """
    return _TruthHook(ws, recorder, status, (vehicle_hz, series_hz, slice_hz, puffs_hz), slice_resolution_m,
                      slice_bounds_ned, field_altitude_m, meter)  # fmt: skip


def _fc_status(sim: Simulation) -> tuple[object, bool]:
    fc = sim.fc
    return fc.mode, fc.armed


def record_simulation(sim: Simulation, recorder: RunRecorder, **rates: Any) -> Callable[[Simulation], None]:
    """:func:`record_world` for a simulation flown by the built-in autopilot (its mode and arming),
    keyword arguments as there. Returns the hook, already appended to ``sim.step_hooks`` (remove it to
    stop recording)."""
    hook = record_world(sim, recorder, status=_fc_status, **rates)
    sim.step_hooks.append(hook)
    return hook


__all__ = ["SLICE_MARGIN_M", "WorldSource", "record_simulation", "record_urban", "record_world",
           "wind_speed_from_deg"]  # fmt: skip
