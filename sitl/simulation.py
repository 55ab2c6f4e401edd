"""The lockstep simulation API: the world flown by the built-in autopilot, ``step()``, truth and sensors.

:class:`Simulation` composes a :class:`~sitl.world.world.World` (vehicle physics, wind, plume,
sensors) and the :class:`~sitl.autopilot.builtin.BuiltinAutopilot` (flight modes + controller).
Plain, synchronous and deterministic: no threads, no asyncio, no I/O. Same scenario and seed give
the same trajectory bit for bit, however the steps are grouped into calls. To fly the world with
another controller, step the :class:`World` with a :class:`~sitl.world.world.RotorCommand` (or
any :class:`~sitl.world.world.Pilot`) instead.

Timing: physics at ``scenario.physics_rate_hz`` (500 Hz, RK4), the controller every physics tick,
the flight modes and the low-rate sensors at ``scenario.mode_rate_hz`` (50 Hz), hooks after them.
All times are simulation time in seconds; frames NED/FRD; SI units.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from sitl.autopilot.builtin import BuiltinAutopilot
from sitl.autopilot.controller import F_IDLE, F_POS, SP_FLAGS, SP_POS
from sitl.autopilot.flight_modes import FlightController
from sitl.scenario import Scenario
from sitl.world.kernel import (
    FLAG_ON_GROUND,
    N_TRUTH,
    T_POS,
    T_QUAT,
    T_RATES,
    T_ROTOR_CMD,
    T_ROTORS,
    T_SPECIFIC_FORCE,
    T_TIME,
    T_VEL,
    T_WIND,
)
from sitl.world.plume.part import PlumePart
from sitl.world.plume.puffs import GaussianPlume, PuffPlume
from sitl.world.sensors import BaroSample, GnssSample, MagSample
from sitl.world.wind.model import WindModel
from sitl.world.world import World
from vehicle.frames import tilt_angle
from vehicle.params import VehicleParams


@dataclass
class RunStats:
    """Running figures of merit (for ``windseek sim``)."""

    pos_err_sq_sum: float = 0.0
    pos_err_n: int = 0
    max_tilt_rad: float = 0.0
    airborne_s: float = 0.0

    @property
    def position_error_rms_m(self) -> float:
        return math.sqrt(self.pos_err_sq_sum / self.pos_err_n) if self.pos_err_n else 0.0


class Simulation:
    """Lockstep multirotor simulation of a :class:`~sitl.scenario.Scenario` with the built-in autopilot.

    Args:
        scenario: the scenario (wind, turbulence, start, route, sensors, gains, plume).
        seed: overrides ``scenario.seed``; every random process is spawned from it.
        vehicle: overrides the scenario's vehicle file.
        autostart_route: arm and fly the scenario's route (``windseek sim``); False leaves
            the vehicle waiting for commands (MAVLink SITL, offboard runners).
        record_truth: keep every truth row (IMU rate) in memory (:meth:`truth_array`).
    """

    def __init__(self, scenario: Scenario, seed: int | None = None, vehicle: VehicleParams | None = None,
                 autostart_route: bool = True, record_truth: bool = False) -> None:  # fmt: skip
        self.world = World(scenario.world_spec(), seed=seed, vehicle=vehicle, record_truth=record_truth)
        self.scenario = scenario
        self.seed = self.world.seed
        self.vehicle = self.world.vehicle
        st = scenario.start
        self.autopilot = BuiltinAutopilot(scenario.flight, scenario.gains,
                                          np.array([st.position_ned[0], st.position_ned[1], 0.0]),
                                          math.radians(st.yaw_deg))  # fmt: skip
        self.stats = RunStats()
        #: callables(sim) run at every slow tick, after the autopilot and the world's sensors.
        self.step_hooks: list[Callable[[Simulation], None]] = []
        #: callables(sim) -> dict of extra summary figures (``windseek sim --json``).
        self.summary_hooks: list[Callable[[Simulation], dict[str, object]]] = []
        self.fc.prearm_checks.append(self._gnss_check)
        if st.airborne:
            self.autopilot.start_hovering(self.world)
        w = self.world
        self.fc.update(0.0, w.phys.x, w.on_ground, False, 1.0 / scenario.mode_rate_hz)
        if autostart_route:
            self._start_route()

    # ------------------------------------------------------------------ parts
    @property
    def fc(self) -> FlightController:
        """The built-in autopilot's commands and state (see :mod:`sitl.autopilot.flight_modes`)."""
        return self.autopilot.fc

    @property
    def wind(self) -> WindModel:
        return self.world.wind

    @property
    def plume(self) -> PuffPlume | GaussianPlume | None:
        """The plume model, or None when the scenario has no ``[plume]``."""
        return self.world.plume.model if self.world.plume is not None else None

    @property
    def chem(self) -> PlumePart | None:
        """The plume with its chemical sensor (readings, latest, summary), or None."""
        return self.world.plume

    @property
    def sensors(self) -> Any:
        return self.world.sensors

    # ------------------------------------------------------------------ set-up
    def _start_route(self) -> None:
        items = self.scenario.mission_items()
        if not items:
            return
        self.fc.set_mission(items)
        if not self.fc.armed:
            ok, why = self.fc.arm()
            if not ok:
                raise RuntimeError(f"cannot arm at start: {why}")
        self.fc.start_mission(0)

    def _gnss_check(self) -> str | None:
        # PX4 refuses to arm without a position fix; here the fix exists once GNSS delivered.
        if self.t < self.scenario.sensors.gnss.latency_s and self.tick > 0:
            return "no GNSS fix yet"
        return None

    # ------------------------------------------------------------------ truth (the world's)
    @property
    def t(self) -> float:
        """Simulation time, s."""
        return self.world.t

    @property
    def tick(self) -> int:
        return self.world.tick

    @property
    def dt(self) -> float:
        return self.world.dt

    @property
    def x(self) -> np.ndarray:
        """The world's state vector (17,) (the array itself)."""
        return self.world.phys.x

    position = property(lambda self: self.world.position, doc="NED position, m.")
    velocity = property(lambda self: self.world.velocity, doc="NED ground velocity, m/s.")
    quaternion = property(lambda self: self.world.quaternion, doc="Attitude [w, x, y, z], body FRD -> NED.")
    rates = property(lambda self: self.world.rates, doc="Body rates (FRD), rad/s.")
    rotor_speeds = property(lambda self: self.world.rotor_speeds, doc="Rotor speeds, rad/s.")
    wind_at_vehicle = property(lambda self: self.world.wind_at_vehicle, doc="True wind at the vehicle, NED, m/s.")
    last_wind = property(lambda self: self.world.last_wind, doc="(t s, NED m/s) the wind the physics used at its "
                         "newest IMU instant (no new sample of the field: wind_at_vehicle samples it again, ~10 us).")
    on_ground = property(lambda self: self.world.on_ground)
    crashed = property(lambda self: self.world.crashed)
    specific_force = property(lambda self: self.world.specific_force, doc="True specific force, FRD, m/s^2.")
    tilt_rad = property(lambda self: self.world.tilt_rad)
    last_truth = property(lambda self: self.world.last_truth, doc="The newest truth row (see sitl.world.kernel).")
    truth_log = property(lambda self: self.world.truth_log)

    @property
    def params(self) -> np.ndarray:
        """The vehicle parameter array the physics uses (see :mod:`vehicle.params`)."""
        return self.world.phys.params

    @property
    def accel_setpoint(self) -> np.ndarray:
        return self.autopilot.accel_sp.copy()

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics ticks (n * dt seconds)."""
        self.world.step(n, self.autopilot, self._after_slow_tick)

    def run(self, duration_s: float) -> None:
        """Advance by ``duration_s`` seconds (rounded to whole ticks)."""
        self.step(int(round(duration_s / self.dt)))

    def run_until(self, t: float) -> None:
        """Advance until simulation time ``t`` (s)."""
        target = int(round(t / self.dt))
        if target > self.tick:
            self.step(target - self.tick)

    def _after_slow_tick(self) -> None:
        w = self.world
        fc = self.autopilot.fc
        st = self.stats
        # Figures of merit: distance to the commanded (moving) setpoint while flying, and the largest tilt.
        flying = fc.armed and w.phys.flags[FLAG_ON_GROUND] == 0.0
        err_sq, tilt = _tracking(w.phys.x, fc.sp, flying)
        if err_sq >= 0.0:
            st.pos_err_sq_sum += err_sq
            st.pos_err_n += 1
            st.airborne_s += w.slow_div * w.phys.dt
        st.max_tilt_rad = max(st.max_tilt_rad, tilt)
        for hook in self.step_hooks:
            hook(self)

    # ------------------------------------------------------------------ outputs
    def drain(self) -> dict[str, list[Any]]:
        """All sensor samples since the previous call, by sensor name, oldest first."""
        return self.world.drain()

    def gain(self, name: str) -> float:
        """Current value of a controller gain (see :class:`sitl.autopilot.controller.ControllerGains`)."""
        return self.autopilot.gain(name)

    def set_gain(self, name: str, value: float) -> None:
        """Change a controller gain in flight (parameter protocol). ValueError if unknown/bad."""
        self.autopilot.set_gain(name, value)

    def summary_extras(self) -> dict[str, object]:
        """Extra figures for ``windseek sim --json``: the world's parts and any summary hooks."""
        out: dict[str, object] = dict(self.world.summary())
        for fn in self.summary_hooks:
            out.update(fn(self))
        return out

    def truth_array(self) -> np.ndarray:
        """All recorded truth rows (needs ``record_truth=True``), shape (K, N_TRUTH)."""
        return self.world.truth_array()


@njit(cache=True)
def _tracking(x: np.ndarray, sp: np.ndarray, flying: bool) -> tuple[float, float]:
    """(squared distance [m^2] from the state ``x``'s position to the setpoint ``sp``'s position when ``flying`` under
    position control, not idle, else -1; the tilt [rad]), for :class:`RunStats` (numpy's ``err @ err``: BLAS)."""
    flags = int(sp[SP_FLAGS])
    err_sq = -1.0
    if flying and flags & F_POS and not flags & F_IDLE:
        err = x[0:3] - sp[SP_POS:SP_POS + 3]
        err_sq = err.dot(err)
    return err_sq, tilt_angle(x[6:10])


# The truth-row columns are part of the lockstep API (they are defined with the physics loop).
__all__ = ["BaroSample", "GnssSample", "MagSample", "N_TRUTH", "Simulation", "T_POS", "T_QUAT", "T_RATES",
           "T_ROTORS", "T_ROTOR_CMD", "T_SPECIFIC_FORCE", "T_TIME", "T_VEL", "T_WIND"]  # fmt: skip
