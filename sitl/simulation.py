"""The lockstep simulation API: build from a scenario, ``step()``, read truth and sensors.

Plain, synchronous and deterministic: no threads, no asyncio, no I/O. Same scenario and seed
give the same trajectory bit for bit, however the steps are grouped into calls.

Timing: physics runs at ``scenario.physics_rate_hz`` (500 Hz by default, RK4); the rate
controller runs every physics tick; the mode logic and the low-rate sensors (GNSS, baro,
magnetometer) run in Python at their own rates; the IMU and ESC telemetry are sampled inside
the numba kernel at their rates and turned into measurements in vectorized batches.
All times are simulation time in seconds; frames NED/FRD; SI units.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from sitl.autopilot.controller import GAIN_NAMES, N_CTRL_STATE, SP_FLAGS, SP_POS, control
from sitl.autopilot.flight_modes import F_IDLE, FlightController, LandedState, Mode
from sitl.scenario import Scenario
from sitl.world.dynamics import N_STATE, rk4_step
from sitl.world.sensors import BaroSample, GnssSample, MagSample, SensorSuite
from sitl.world.wind import WindField, wind_velocity
from vehicle.frames import euler_to_quat, quat_to_dcm, tilt_angle
from vehicle.params import P_WMIN, VehicleParams, load_vehicle
from vehicle.rotor_model import hover_rotor_speed

# Columns of a truth row, recorded at every IMU sample instant.
T_TIME = 0
T_SPECIFIC_FORCE = slice(1, 4)  # FRD, m/s^2
T_RATES = slice(4, 7)  # FRD, rad/s
T_ROTORS = slice(7, 11)  # rad/s
T_POS = slice(11, 14)  # NED, m
T_VEL = slice(14, 17)  # NED, m/s
T_QUAT = slice(17, 21)  # body -> NED
T_WIND = slice(21, 24)  # air-mass velocity at the vehicle, NED, m/s
T_ROTOR_CMD = slice(24, 28)  # rad/s
N_TRUTH = 28


@njit(cache=True)
def _advance(
    n: int,
    tick0: int,
    dt: float,
    x: np.ndarray,
    flags: np.ndarray,
    p: np.ndarray,
    gains: np.ndarray,
    cs: np.ndarray,
    sp: np.ndarray,
    imu_div: int,
    rows: np.ndarray,
    accel_sp: np.ndarray,
    fb: np.ndarray,
    wargs: tuple,
) -> int:
    """Run ``n`` physics ticks in place. ``flags`` = [on_ground, crashed, touchdown speed
    (max so far), collision count]. Returns the number of truth rows written to ``rows``."""
    nrow = 0
    w_cmd = np.zeros(4)
    idle = int(sp[SP_FLAGS]) == 64
    for k in range(n):
        tick = tick0 + k
        t = tick * dt
        wind = wind_velocity(t, x[0:3], *wargs)
        if flags[1] != 0.0:
            w_cmd[:] = 0.0
        elif idle:
            w_cmd[:] = p[P_WMIN]
            cs[:] = 0.0
        else:
            w_cmd = control(x, sp, gains, cs, p, dt, accel_sp)
        on_ground = flags[0] != 0.0
        xn, og, vtd = rk4_step(x, w_cmd, wind, p, dt, on_ground, fb)
        if tick % imu_div == 0:
            r = rows[nrow]
            r[0] = t
            r[1:4] = fb
            r[4:7] = x[10:13]
            r[7:11] = x[13:17]
            r[11:14] = x[0:3]
            r[14:17] = x[3:6]
            r[17:21] = x[6:10]
            r[21:24] = wind
            r[24:28] = w_cmd
            nrow += 1
        x[:] = xn
        flags[0] = 1.0 if og else 0.0
        if vtd > flags[2]:
            flags[2] = vtd
        if vtd > 0.0 and vtd > gains[-1]:
            flags[1] = 1.0
    return nrow


@dataclass
class SensorOutputs:
    """Sensor samples since the last :meth:`Simulation.drain` (bounded queues) and the latest."""

    maxlen: int = 100_000
    imu: deque = field(default_factory=deque)  # (t, accel FRD m/s^2 (3,), gyro FRD rad/s (3,))
    esc: deque = field(default_factory=deque)  # (t, rotor speeds rad/s (4,))
    gnss: deque = field(default_factory=deque)  # GnssSample
    baro: deque = field(default_factory=deque)  # BaroSample
    mag: deque = field(default_factory=deque)  # MagSample
    extra: dict[str, deque] = field(default_factory=dict)  # e.g. "chem" from the plume issue

    def __post_init__(self) -> None:
        for name in ("imu", "esc", "gnss", "baro", "mag"):
            setattr(self, name, deque(maxlen=self.maxlen))


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
    """Lockstep multirotor simulation of a :class:`~sitl.scenario.Scenario`.

    Args:
        scenario: the scenario (wind, turbulence, start, route, sensors, gains).
        seed: overrides ``scenario.seed``; every random process is spawned from it.
        vehicle: overrides the scenario's vehicle file.
        autostart_route: arm and fly the scenario's route (``windseek sim``); False leaves
            the vehicle waiting for commands (MAVLink SITL, offboard runners).
        record_truth: keep every truth row (IMU rate) in memory (:attr:`truth_log`).
    """

    def __init__(
        self,
        scenario: Scenario,
        seed: int | None = None,
        vehicle: VehicleParams | None = None,
        autostart_route: bool = True,
        record_truth: bool = False,
    ) -> None:
        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        ss = np.random.SeedSequence(self.seed)
        s_wind, s_sensors, self._seed_extra = ss.spawn(3)
        self.vehicle = vehicle or load_vehicle(scenario.vehicle)
        self.params = self.vehicle.as_array()
        self.dt = 1.0 / scenario.physics_rate_hz
        self.tick = 0
        sc = scenario.sensors
        rate = scenario.physics_rate_hz
        self.imu_div = round(rate / sc.imu.rate_hz)
        self.esc_every = max(1, round(sc.imu.rate_hz / sc.esc.rate_hz))
        self.mode_div = round(rate / scenario.mode_rate_hz)
        self.gnss_div = round(rate / sc.gnss.rate_hz)
        self.baro_div = round(rate / sc.baro.rate_hz)
        self.mag_div = round(rate / sc.mag.rate_hz)
        self.wind = WindField(scenario.wind, scenario.turbulence, s_wind)
        self._wargs = self.wind.kernel_args()
        self.sensors = SensorSuite(sc, s_sensors)
        self.outputs = SensorOutputs()
        # Gains array + crash threshold appended (read by the kernel as gains[-1]).
        self._gains = np.append(scenario.gains.as_array(), self.vehicle.crash_speed_m_s)
        self._cs = np.zeros(N_CTRL_STATE)
        self._flags = np.zeros(4)
        self._accel_sp = np.zeros(3)
        self._fb = np.zeros(3)
        self._rows = np.zeros((self.mode_div // self.imu_div + 2, N_TRUTH))
        self._imu_count = 0
        self.last_truth = np.zeros(N_TRUTH)
        self.truth_log: list[np.ndarray] | None = [] if record_truth else None
        self.stats = RunStats()
        self.step_hooks: list = []  # callables(sim) run at every mode tick (plume, sensors)
        self.summary_hooks: list = []  # callables(sim) -> dict of summary figures
        self.x = np.zeros(N_STATE)
        st = scenario.start
        yaw = math.radians(st.yaw_deg)
        self.x[0:3] = st.position_ned
        self.x[6:10] = euler_to_quat(0.0, 0.0, yaw)
        self.fc = FlightController(scenario.flight, home_yaw=yaw)
        self.fc.home = np.array([st.position_ned[0], st.position_ned[1], 0.0])
        self.fc.prearm_checks.append(self._gnss_check)
        if st.airborne:
            self._start_hovering()
        else:
            self._flags[0] = 1.0
        self.fc.update(0.0, self.x, self._flags[0] != 0.0, False, 1.0 / scenario.mode_rate_hz)
        if autostart_route:
            self._start_route()
        if scenario.plume is not None:
            from sitl.world.plume_attach import attach_plume

            attach_plume(self)

    # ------------------------------------------------------------------ set-up
    def _start_hovering(self) -> None:
        """Initial condition: armed, holding, trimmed for the wind at the start point.

        The trim is found "captive": the vehicle is held at its start position and velocity
        (like a test stand) for a few simulated seconds at t = 0 while attitude, rotor speeds
        and controller integrators settle. Time does not advance and no sensor samples are
        produced, so a run starts in steady hover instead of being blown off its point.
        """
        self.x[13:17] = hover_rotor_speed(self.vehicle)
        self._flags[0] = 0.0
        fc = self.fc
        fc._on_ground = False
        fc._pos = self.x[0:3].copy()
        fc.armed = True
        fc.landed_state = LandedState.IN_AIR
        fc._traj.reset(self.x[0:3])
        fc.mode = Mode.HOLD
        fc.update(0.0, self.x, False, False, 1.0 / self.scenario.mode_rate_hz)
        hold = self.x[0:6].copy()
        rows = np.zeros((2, N_TRUTH))
        lim = self.scenario.gains.vel_int_lim
        for _ in range(int(round(6.0 / self.dt))):
            _advance(
                1, 0, self.dt, self.x, self._flags, self.params, self._gains, self._cs,
                fc.sp, self.imu_div, rows, self._accel_sp, self._fb, self._wargs,
            )  # fmt: skip
            # The stand measures the acceleration it prevents and trims the velocity-loop
            # integrators against it, so the release finds the vehicle already leaning in.
            accel = (self.x[3:6] - hold[3:6]) / self.dt
            self._cs[0:3] = np.clip(self._cs[0:3] - 2.0 * accel * self.dt, -lim, lim)
            self.x[0:6] = hold

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
        if self.tick * self.dt < self.scenario.sensors.gnss.latency_s and self.tick > 0:
            return "no GNSS fix yet"
        return None

    # ------------------------------------------------------------------ truth
    @property
    def t(self) -> float:
        """Simulation time, s."""
        return self.tick * self.dt

    @property
    def position(self) -> np.ndarray:
        """NED position, m."""
        return self.x[0:3].copy()

    @property
    def velocity(self) -> np.ndarray:
        """NED ground velocity, m/s."""
        return self.x[3:6].copy()

    @property
    def quaternion(self) -> np.ndarray:
        """Attitude quaternion [w, x, y, z], body FRD -> NED."""
        return self.x[6:10].copy()

    @property
    def rates(self) -> np.ndarray:
        """Body rates (FRD), rad/s."""
        return self.x[10:13].copy()

    @property
    def rotor_speeds(self) -> np.ndarray:
        """Rotor speeds, rad/s."""
        return self.x[13:17].copy()

    @property
    def wind_at_vehicle(self) -> np.ndarray:
        """True air-mass velocity at the vehicle now (mean + turbulence), NED, m/s."""
        return self.wind.velocity(self.t, self.x[0:3])

    @property
    def on_ground(self) -> bool:
        return bool(self._flags[0])

    @property
    def crashed(self) -> bool:
        return bool(self._flags[1])

    @property
    def specific_force(self) -> np.ndarray:
        """True specific force (FRD, m/s^2) at the last tick."""
        return self._fb.copy()

    @property
    def accel_setpoint(self) -> np.ndarray:
        return self._accel_sp.copy()

    @property
    def tilt_rad(self) -> float:
        return float(tilt_angle(self.x[6:10]))

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics ticks (n * dt seconds)."""
        if n < 0:
            raise ValueError(f"step(n={n}): n must be >= 0")
        while n > 0:
            tick = self.tick
            if tick % self.mode_div == 0:
                self._mode_tick()
            k = min(n, self.mode_div - tick % self.mode_div)
            nrow = _advance(
                k, tick, self.dt, self.x, self._flags, self.params, self._gains, self._cs,
                self.fc.sp, self.imu_div, self._rows, self._accel_sp, self._fb, self._wargs,
            )  # fmt: skip
            if nrow:
                self._imu_batch(self._rows[:nrow])
            self.tick += k
            n -= k

    def run(self, duration_s: float) -> None:
        """Advance by ``duration_s`` seconds (rounded to whole ticks)."""
        self.step(int(round(duration_s / self.dt)))

    def run_until(self, t: float) -> None:
        """Advance until simulation time ``t`` (s)."""
        target = int(round(t / self.dt))
        if target > self.tick:
            self.step(target - self.tick)

    # ------------------------------------------------------------------ internals
    def _mode_tick(self) -> None:
        t = self.t
        x = self.x
        dt_mode = self.mode_div * self.dt
        self.fc.update(t, x, self.on_ground, self.crashed, dt_mode)
        tick = self.tick
        if tick % self.gnss_div == 0:
            self.sensors.gnss_measure(t, x[0:3], x[3:6])
        for s in self.sensors.gnss_deliver(t):
            self.outputs.gnss.append(s)
        if tick % self.baro_div == 0:
            self.outputs.baro.append(self.sensors.baro(t, x[0:3]))
        if tick % self.mag_div == 0:
            self.outputs.mag.append(self.sensors.mag(t, quat_to_dcm(x[6:10])))
        # Figures of merit: distance to the commanded (moving) setpoint while flying.
        flags = int(self.fc.sp[SP_FLAGS])
        if self.fc.armed and not self.on_ground and flags & 1 and not flags & F_IDLE:
            err = x[0:3] - self.fc.sp[SP_POS:SP_POS + 3]
            self.stats.pos_err_sq_sum += float(err @ err)
            self.stats.pos_err_n += 1
            self.stats.airborne_s += dt_mode
        self.stats.max_tilt_rad = max(self.stats.max_tilt_rad, self.tilt_rad)
        for hook in self.step_hooks:
            hook(self)

    def _imu_batch(self, rows: np.ndarray) -> None:
        acc, gyr = self.sensors.imu(rows[:, T_SPECIFIC_FORCE], rows[:, T_RATES])
        out = self.outputs
        for i in range(rows.shape[0]):
            out.imu.append((rows[i, 0], acc[i], gyr[i]))
        k0 = self._imu_count
        sel = [i for i in range(rows.shape[0]) if (k0 + i) % self.esc_every == 0]
        if sel:
            meas = self.sensors.esc(rows[sel][:, T_ROTORS])
            for i, m in zip(sel, meas, strict=True):
                out.esc.append((rows[i, 0], m))
        self._imu_count += rows.shape[0]
        self.last_truth = rows[-1].copy()
        if self.truth_log is not None:
            self.truth_log.append(rows.copy())

    # ------------------------------------------------------------------ outputs
    def drain(self) -> dict[str, list]:
        """All sensor samples since the previous call, by sensor name, oldest first."""
        out = {}
        for name in ("imu", "esc", "gnss", "baro", "mag"):
            q = getattr(self.outputs, name)
            out[name] = list(q)
            q.clear()
        for name, q in self.outputs.extra.items():
            out[name] = list(q)
            q.clear()
        return out

    # ------------------------------------------------------------------ live tuning
    def gain(self, name: str) -> float:
        """Current value of a controller gain (see :class:`sitl.autopilot.controller.ControllerGains`)."""
        return float(self._gains[GAIN_NAMES.index(name)])

    def set_gain(self, name: str, value: float) -> None:
        """Change a controller gain in flight (parameter protocol). ValueError if unknown/bad."""
        if name not in GAIN_NAMES:
            raise ValueError(f"unknown gain {name!r}; allowed: {', '.join(GAIN_NAMES)}")
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"gain {name} = {value!r}: must be finite and >= 0")
        self._gains[GAIN_NAMES.index(name)] = float(value)

    def summary_extras(self) -> dict[str, object]:
        """Extra figures for ``windseek sim --json`` contributed by attached models."""
        out: dict[str, object] = {}
        for fn in self.summary_hooks:
            out.update(fn(self))
        return out

    def truth_array(self) -> np.ndarray:
        """All recorded truth rows (needs ``record_truth=True``), shape (K, N_TRUTH)."""
        if self.truth_log is None:
            raise RuntimeError("Simulation(record_truth=True) is needed for truth_array()")
        if not self.truth_log:
            return np.zeros((0, N_TRUTH))
        return np.concatenate(self.truth_log)


__all__ = [
    "BaroSample",
    "GnssSample",
    "MagSample",
    "Simulation",
    "N_TRUTH",
]
