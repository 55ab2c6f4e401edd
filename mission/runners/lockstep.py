"""The simulator as a :class:`~mission.vehicle.Vehicle`: the built-in autopilot in lockstep, no I/O.

Every wait advances the simulation by whole strategy ticks (``1 / rate_hz`` of simulation time, on
a fixed grid from t = 0) instead of sleeping, so a mission runs as fast as the machine allows and
is reproducible bit for bit. At each tick the sensor samples are drained and handed to the
in-process wind source (which runs through the take-off, as a real estimator would), and the
state is refreshed: the autopilot's estimate is the truth (it flies on the true state, as PX4
SITL with a ground-truth estimator), the strategy observes the raw GNSS fix (noise, latency),
the chemical reading is the sensor's.

Commands go straight to the flight controller (:class:`~sitl.autopilot.flight_modes.FlightController`);
a refused one raises :class:`~mission.vehicle.CommandError` with the autopilot's reason.
Units SI, NED; times are simulation seconds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from mission.strategies.base import WindInfo
from mission.vehicle import CommandError, VehicleState, Wait
from mission.wind_source import WindSource
from sitl.autopilot.modes import Mode
from sitl.simulation import Simulation
from vehicle.frames import quat_to_euler


class LockstepVehicle:
    """A :class:`Simulation` flown through the mission interface (see the module docstring).

    Args:
        sim: built with ``autostart_route=False`` (the vehicle waits on the ground).
        wind_source: the in-process wind source fed at every tick (``estimated``, ``oracle``, ``none``).
        rate_hz: the strategy tick rate (the grid the simulation advances on).
        say: where lines go (default: nowhere; batch runs are quiet).
    """

    def __init__(self, sim: Simulation, wind_source: WindSource, rate_hz: float,
                 say: Callable[[str], None] | None = None) -> None:  # fmt: skip
        self.sim = sim
        self.fc = sim.fc
        self.wind_source = wind_source
        self.dt = 1.0 / rate_hz
        self.k = 0
        self._say = say
        self.wind_info: WindInfo | None = None
        self.published: list[tuple[str, str]] = []
        #: callables(t) run after every simulated tick (scoring, tracks), from the first on.
        self.tick_hooks: list[Callable[[float], None]] = []
        self.state = VehicleState()
        self._refresh()

    # ------------------------------------------------------------------ state
    def _refresh(self) -> None:
        sim, st, fc = self.sim, self.state, self.fc
        st.t = sim.t
        st.pos = sim.position
        st.vel = sim.velocity
        st.yaw = float(quat_to_euler(sim.quaternion)[2])
        st.armed = fc.armed
        st.mode = fc.mode.value
        st.landed = int(fc.landed_state)
        st.crashed = sim.crashed
        st.heartbeat_seq += 1

    def _tick(self) -> None:
        """One strategy tick of simulation; samples to the wind source; the state refreshed."""
        self.k += 1
        self.sim.run_until(self.k * self.dt)
        out = self.sim.drain()
        self.wind_info = self.wind_source.update(out)
        st = self.state
        if out["gnss"]:
            g = out["gnss"][-1]
            st.obs_pos = np.asarray(g.pos_ned, dtype=float)
            st.obs_vel = np.asarray(g.vel_ned, dtype=float)
        chem = out.get("chem", [])
        if chem:
            st.chem = float(chem[-1].value_mg_m3)
            st.chem_seq += len(chem)
            st.chem_t = float(chem[-1].t)
        self._refresh()
        for hook in self.tick_hooks:
            hook(st.t)

    def say(self, line: str) -> None:
        if self._say is not None:
            self._say(line)

    # ------------------------------------------------------------------ waits
    async def wait(self, pred: Callable[[], bool], vehicle_s: float, wall_s: float | None = None) -> Wait:
        t0 = self.state.t
        while not pred():
            if self.state.t - t0 >= vehicle_s - 1e-9:
                return Wait.TIMEOUT
            self._tick()
        return Wait.OK

    async def next_tick(self, t_next: float) -> Wait:
        while self.state.t < t_next - 1e-9:
            self._tick()
        return Wait.OK

    def link_lost(self) -> str | None:
        return None

    async def await_link(self, grace_s: float) -> bool:
        return True

    # ------------------------------------------------------------------ commands
    @staticmethod
    def _check(result: tuple[bool, str], what: str) -> None:
        ok, why = result
        if not ok:
            raise CommandError(f"{what} refused: {why}")

    async def arm(self) -> None:
        self._check(self.fc.arm(), "arm")
        self._refresh()

    async def takeoff(self, altitude_m: float) -> None:
        self._check(self.fc.takeoff(altitude_m), "take-off")
        self._refresh()

    async def start_offboard(self) -> None:
        self._check(self.fc.set_mode(Mode.OFFBOARD), "offboard")
        self._refresh()

    async def stop_offboard(self) -> None:
        pass

    def send_setpoint(self, pos: np.ndarray | None, vel: np.ndarray | None, yaw: float | None) -> None:
        self.fc.offboard_setpoint(self.sim.t, pos=pos, vel=vel, yaw=yaw)

    async def hold(self) -> None:
        self._check(self.fc.hold(), "hold")

    async def land(self) -> None:
        self._check(self.fc.land(), "land")

    def publish(self, pairs: list[tuple[str, str]]) -> None:
        self.published.extend(pairs)


class InProcessWind:
    """The in-process wind source as the mission loop's :class:`~mission.loop.MissionWind`: the
    lockstep vehicle feeds it every tick; the loop reads the newest :class:`WindInfo`."""

    def __init__(self, vehicle: LockstepVehicle) -> None:
        self.vehicle = vehicle
        self.mode = vehicle.wind_source.mode

    def info(self, t: float) -> WindInfo | None:
        return self.vehicle.wind_info

    def ready(self) -> bool:
        est = getattr(self.vehicle.wind_source, "estimator", None)
        return self.mode != "none" and (est is None or est.t is not None)

    def missing(self) -> str:
        return "" if self.ready() else "no estimator input accepted yet"

    def fault(self, t: float) -> Any:
        return None

    def describe(self) -> str:
        return {"estimated": "the UKF on the simulated IMU, ESC and GNSS samples (in-process)",
                "oracle": "the simulator's true mean wind (oracle, comparison only)",
                "none": "none: pure chemotaxis"}.get(self.mode, self.mode)  # fmt: skip

    def report(self) -> dict[str, Any]:
        est = getattr(self.vehicle.wind_source, "estimator", None)
        if est is None:
            return {}
        return {"accepted": dict(est.accepted), "rejected": dict(est.rejected),
                "restarts": int(getattr(self.vehicle.wind_source, "restarts", 0)),
                "span_s": float(est.span_s) if math.isfinite(est.span_s) else math.nan}  # fmt: skip
