"""The world: the vehicle's physics, the wind, the plume and the sensors, stepped with rotor commands.

:class:`World` is what a real vehicle experiences and nothing more: it takes rotor commands and
returns sensor samples (:meth:`World.drain`) and truth (the ``position`` ... properties, truth
rows). It has no autopilot inside. Something that produces rotor commands is a :class:`Pilot`:

- :class:`RotorCommand`: commanded rotor speeds held between updates, set from outside (an
  external controller, PX4 over HIL, a test);
- the built-in autopilot (:class:`sitl.autopilot.builtin.BuiltinAutopilot`), which computes its
  rotor commands inside a fused numba loop for speed, through the same :func:`physics_tick`.

Timing: physics runs at ``scenario.physics_rate_hz`` (500 Hz by default, RK4). At every slow tick
(``scenario.mode_rate_hz``, 50 Hz) the pilot's slow logic runs first, then the low-rate sensors
(GNSS, barometer, magnetometer) and the plume and chemical sensor; the IMU and ESC samples come
from the truth rows the physics loop writes at the IMU rate, turned into measurements in one
compiled call per control period (:mod:`sitl.world.sensor_kernel`). Same scenario, seed and
commands give the same trajectory bit for bit, however the steps are grouped.

Seeding: ``SeedSequence(seed).spawn(3)`` = (wind, sensors, extra); the plume is spawned from
``extra``. Units SI; NED world, FRD body; wind = air-mass velocity NED.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from sitl.world.dynamics import IX_INFLOW, IX_ROTORS, N_STATE
from sitl.world.kernel import (
    FLAG_COLLISIONS,
    FLAG_CRASHED,
    FLAG_ON_GROUND,
    N_TRUTH,
    NO_OBSTACLES,
    T_WIND,
    Obstacles,
    advance_commanded,
)
from sitl.world.plume.part import CHEM_OUTPUT, PlumePart
from sitl.world.sensor_kernel import DUE_BARO, DUE_GNSS, DUE_MAG
from sitl.world.sensors import SensorSuite
from sitl.world.spec import WorldSpec
from sitl.world.wind.kernel import WindKernel
from sitl.world.wind.model import WindModel, make_wind
from vehicle.frames import euler_to_quat, tilt_angle
from vehicle.params import MAX_ROTORS, VehicleParams
from vehicle.vehicle_file import load_vehicle

#: Sensor samples kept between two ``drain()`` calls, per sensor (the oldest are dropped).
SENSOR_QUEUE_MAXLEN = 100_000


@dataclass
class PhysicsArrays:
    """The arrays the physics loop works on in place: the explicit boundary between the world and
    a pilot that runs its own compiled loop (the built-in autopilot's fused path).

    x: state (N_STATE,): position NED m, velocity NED m/s, quaternion body->NED, rates FRD rad/s,
        rotor speeds rad/s, rotor inflows m/s (see :mod:`sitl.world.dynamics`).
        flags: (4,) [on_ground, crashed, touchdown speed m/s, collisions].
    params: the vehicle parameter array; crash_speed: touchdown speed that is a crash, m/s.
    rows: truth-row buffer (one slow tick of IMU samples); fb: specific force at the last tick.
    imu_div: physics ticks per IMU sample; dt: physics step, s.
    obstacles: the buildings (a vehicle that enters one has crashed).
    """

    x: np.ndarray
    flags: np.ndarray
    params: np.ndarray
    crash_speed: float
    rows: np.ndarray
    fb: np.ndarray
    imu_div: int
    dt: float
    obstacles: Obstacles = NO_OBSTACLES


class Pilot(Protocol):
    """A source of rotor commands for the world."""

    def on_slow_tick(self, world: World) -> None:
        """Slow logic at each slow tick (``mode_rate_hz``), before the world's slow sensors."""
        ...

    def advance(self, world: World, n: int) -> int:
        """Run ``n`` physics ticks from ``world.tick`` (not crossing a slow tick) with this pilot's
        rotor commands on ``world.phys``; return the number of truth rows written."""
        ...


class RotorCommand:
    """Commanded rotor speeds (rad/s, the vehicle's rotor order) held until the next :meth:`set`, for a
    vehicle with ``n_rotors`` rotors (``World.n_rotors``)."""

    def __init__(self, n_rotors: int = 4) -> None:
        if not 1 <= n_rotors <= MAX_ROTORS:
            raise ValueError(f"rotor command: n_rotors = {n_rotors}, allowed 1-{MAX_ROTORS}")
        self.n_rotors = n_rotors
        self._buffer = np.zeros(MAX_ROTORS)  # what the physics loop reads (MAX_ROTORS slots)
        self.speeds = self._buffer[:n_rotors]  # a view: writing it writes the buffer

    def set(self, speeds_rad_s: np.ndarray) -> None:
        """New command (one speed per rotor), rad/s; NaN or negative values are refused (ValueError)."""
        w = np.asarray(speeds_rad_s, dtype=float)
        if w.shape != (self.n_rotors,) or not np.all(np.isfinite(w)) or np.any(w < 0.0):
            raise ValueError(f"rotor command must be {self.n_rotors} finite speeds >= 0 rad/s, got {speeds_rad_s!r}")
        self.speeds[:] = w

    def on_slow_tick(self, world: World) -> None:
        pass

    def advance(self, world: World, n: int) -> int:
        ph = world.phys
        return advance_commanded(n, world.tick, ph.dt, ph.x, self._buffer, ph.flags, ph.params, ph.crash_speed,
                                 ph.imu_div, ph.rows, ph.fb, world.wind_kernel, ph.obstacles)  # fmt: skip


class World:
    """The simulated world of a :class:`~sitl.world.spec.WorldSpec` (see the module docstring).

    Args:
        spec: vehicle, rates, wind, turbulence, start, sensors, plume, buildings
            (:meth:`sitl.scenario.Scenario.world_spec` makes one from a scenario).
        seed: overrides ``spec.seed``; every random process is spawned from it.
        vehicle: overrides the scenario's vehicle file.
        record_truth: keep every truth row (IMU rate) in memory (:meth:`truth_array`).
    """

    def __init__(self, spec: WorldSpec, seed: int | None = None, vehicle: VehicleParams | None = None,
                 record_truth: bool = False) -> None:  # fmt: skip
        if not isinstance(spec, WorldSpec):  # a Scenario passed whole: the world takes only its own spec
            raise TypeError(f"World takes a WorldSpec (Scenario.world_spec()), got {type(spec).__name__}")
        self.spec = scenario = spec
        self.seed = scenario.seed if seed is None else int(seed)
        s_wind, s_sensors, s_extra = np.random.SeedSequence(self.seed).spawn(3)
        self.vehicle = vehicle or load_vehicle(scenario.vehicle)
        self.tick = 0
        rate = scenario.physics_rate_hz
        sc = scenario.sensors
        dt = 1.0 / rate
        imu_div = round(rate / sc.imu.rate_hz)
        self.slow_div = round(rate / scenario.mode_rate_hz)
        self.esc_every = max(1, round(sc.imu.rate_hz / sc.esc.rate_hz))
        self.gnss_div = round(rate / sc.gnss.rate_hz)
        self.baro_div = round(rate / sc.baro.rate_hz)
        self.mag_div = round(rate / sc.mag.rate_hz)
        self.wind: WindModel = make_wind(scenario.wind_model, scenario.wind, scenario.turbulence,
                                         dict(scenario.wind_options), s_wind)  # fmt: skip
        kernel = self.wind.kernel()
        self._python_wind = kernel is None
        # A model without a numba fast path is sampled in Python once per tick into this held kernel.
        self.wind_kernel: WindKernel = kernel if kernel is not None else _held_wind_kernel()
        batch_rows = self.slow_div // imu_div + 2  # truth rows (IMU samples) of one control period, at most
        self.sensors = SensorSuite(sc, s_sensors, self.vehicle.n_rotors, batch_rows, SENSOR_QUEUE_MAXLEN)
        self._due = [(div, bit) for div, bit in ((self.gnss_div, DUE_GNSS), (self.baro_div, DUE_BARO),
                                                  (self.mag_div, DUE_MAG))]  # fmt: skip
        x = np.zeros(N_STATE)
        st = scenario.start
        x[0:3] = st.position_ned
        x[6:10] = euler_to_quat(0.0, 0.0, math.radians(st.yaw_deg))
        flags = np.zeros(4)
        flags[FLAG_ON_GROUND] = 0.0 if st.airborne else 1.0
        self.phys = PhysicsArrays(x=x, flags=flags, params=self.vehicle.as_array(),
                                  crash_speed=float(self.vehicle.crash_speed_m_s),
                                  rows=np.zeros((batch_rows, N_TRUTH)), fb=np.zeros(3),
                                  imu_div=imu_div, dt=dt, obstacles=_obstacles(scenario))  # fmt: skip
        self._imu_count = 0
        self.last_truth = np.zeros(N_TRUTH)
        self.truth_log: list[np.ndarray] | None = [] if record_truth else None
        self.plume: PlumePart | None = None
        if scenario.plume is not None:
            self.plume = PlumePart(scenario.plume, self.wind, s_extra, scenario.mode_rate_hz,
                                   obstacles=self.phys.obstacles)  # fmt: skip

    # ------------------------------------------------------------------ truth
    @property
    def dt(self) -> float:
        """Physics step, s."""
        return self.phys.dt

    @property
    def t(self) -> float:
        """Simulation time, s."""
        return self.tick * self.phys.dt

    @property
    def x(self) -> np.ndarray:
        """The state vector (N_STATE,) (see :class:`PhysicsArrays`); the array itself, not a copy."""
        return self.phys.x

    @property
    def n_rotors(self) -> int:
        return self.vehicle.n_rotors

    @property
    def position(self) -> np.ndarray:
        """NED position, m."""
        return self.phys.x[0:3].copy()

    @property
    def velocity(self) -> np.ndarray:
        """NED ground velocity, m/s."""
        return self.phys.x[3:6].copy()

    @property
    def quaternion(self) -> np.ndarray:
        """Attitude quaternion [w, x, y, z], body FRD -> NED."""
        return self.phys.x[6:10].copy()

    @property
    def rates(self) -> np.ndarray:
        """Body rates (FRD), rad/s."""
        return self.phys.x[10:13].copy()

    @property
    def rotor_speeds(self) -> np.ndarray:
        """Rotor speeds (N,), rad/s."""
        return self.phys.x[IX_ROTORS:IX_ROTORS + self.vehicle.n_rotors].copy()

    def set_hover_rotors(self) -> None:
        """Rotors at the truth's hover speed with their inflow settled (an airborne start)."""
        n = self.vehicle.n_rotors
        self.phys.x[IX_ROTORS:IX_ROTORS + n] = self.vehicle.control["hover_speed"]
        self.phys.x[IX_INFLOW:IX_INFLOW + n] = self.vehicle.hover_induced_velocity_m_s

    @property
    def wind_at_vehicle(self) -> np.ndarray:
        """True air-mass velocity at the vehicle now (mean + turbulence), NED, m/s."""
        return np.asarray(self.wind.velocity(self.t, self.phys.x[0:3]), dtype=float)

    @property
    def last_wind(self) -> tuple[float, np.ndarray]:
        """(time [s], air-mass velocity NED [m/s]) the physics used at its newest IMU instant, at most
        one IMU period ago: no new sample of the field. Before the first IMU instant: now, sampled."""
        if self._imu_count == 0:
            return self.t, self.wind_at_vehicle
        return float(self.last_truth[0]), self.last_truth[T_WIND]

    @property
    def on_ground(self) -> bool:
        return bool(self.phys.flags[FLAG_ON_GROUND])

    @property
    def crashed(self) -> bool:
        return bool(self.phys.flags[FLAG_CRASHED])

    @property
    def collisions(self) -> int:
        """Physics ticks that would have ended inside a building (each one a crash)."""
        return int(self.phys.flags[FLAG_COLLISIONS])

    @property
    def specific_force(self) -> np.ndarray:
        """True specific force (FRD, m/s^2) at the last tick."""
        return self.phys.fb.copy()

    @property
    def tilt_rad(self) -> float:
        return float(tilt_angle(self.phys.x[6:10]))

    # ------------------------------------------------------------------ stepping
    def step(self, n: int, pilot: Pilot, after_slow_tick: Callable[[], None] | None = None) -> None:
        """Advance ``n`` physics ticks with the rotor commands of ``pilot``; ``after_slow_tick`` runs
        at every slow tick after the world's own slow sensors and plume."""
        if n < 0:
            raise ValueError(f"step(n={n}): n must be >= 0")
        while n > 0:
            tick = self.tick
            if tick % self.slow_div == 0:
                pilot.on_slow_tick(self)
                self._slow_tick()
                if after_slow_tick is not None:
                    after_slow_tick()
            k = min(n, self.slow_div - tick % self.slow_div)
            nrow = self._advance(pilot, k)
            if nrow:
                self._imu_batch(nrow)
            self.tick += k
            n -= k

    def _advance(self, pilot: Pilot, k: int) -> int:
        if not self._python_wind:
            return pilot.advance(self, k)
        # A Python wind model: one tick at a time, the wind sampled in Python and held over the tick.
        held = self.wind_kernel.sched_vel
        nrow = 0
        rows = self.phys.rows
        for _ in range(k):
            held[0, :] = self.wind.velocity(self.t, self.phys.x[0:3])
            self.phys.rows = rows[nrow:]
            nrow += pilot.advance(self, 1)
            self.tick += 1
        self.phys.rows = rows
        self.tick -= k
        return nrow

    def _slow_tick(self) -> None:
        tick = self.tick
        due = 0
        for div, bit in self._due:
            if tick % div == 0:
                due |= bit
        x = self.phys.x
        self.sensors.slow_tick(self.t, x, due)
        if self.plume is not None:
            self.plume.on_slow_tick(tick // self.slow_div, self.t, x[0:3])

    def _imu_batch(self, nrow: int) -> None:
        """The IMU samples of the first ``nrow`` truth rows and the ESC samples among them (every
        ``esc_every``-th IMU sample, counted across batches)."""
        rows = self.phys.rows
        self.sensors.imu_batch(rows, nrow, -self._imu_count % self.esc_every, self.esc_every)
        self._imu_count += nrow
        self.last_truth = rows[nrow - 1].copy()
        if self.truth_log is not None:
            self.truth_log.append(rows[:nrow].copy())

    # ------------------------------------------------------------------ outputs
    def drain(self) -> dict[str, list[Any]]:
        """All sensor samples since the previous call, by sensor name, oldest first
        (``imu``, ``esc``, ``gnss``, ``baro``, ``mag``, and ``chem`` with a plume)."""
        out = self.sensors.drain()
        if self.plume is not None:
            out[CHEM_OUTPUT] = list(self.plume.readings)
            self.plume.readings.clear()
        return out

    def summary(self) -> dict[str, object]:
        """Figures of the world's parts for ``windseek sim --json`` (the plume's)."""
        return self.plume.summary() if self.plume is not None else {}

    def truth_array(self) -> np.ndarray:
        """All recorded truth rows (needs ``record_truth=True``), shape (K, N_TRUTH)."""
        if self.truth_log is None:
            raise RuntimeError("record_truth=True is needed for truth_array()")
        if not self.truth_log:
            return np.zeros((0, N_TRUTH))
        return np.concatenate(self.truth_log)


def _obstacles(scenario: WorldSpec) -> Obstacles:
    """The scenario's buildings as prisms for the physics loop and the plume (none: empty arrays)."""
    if scenario.urban is None or not scenario.urban.buildings:
        return NO_OBSTACLES
    from urbanflow.geometry import BuildingArrays

    b = BuildingArrays.from_buildings(scenario.urban.buildings)
    return Obstacles(b.verts, b.offsets, b.heights, b.bbox)


def _held_wind_kernel() -> WindKernel:
    """A uniform, turbulence-free kernel whose one velocity is overwritten before every tick."""
    return WindKernel(np.array([-np.inf]), np.zeros((1, 3)), False, 0.1, 1.0, False, False, 1.0, np.zeros((0, 3)))
