"""Any MAVLink autopilot through MAVSDK (4.x, ``mavsdk.asyncio``) as a :class:`~mission.vehicle.Vehicle`.

Telemetry never queues on the asyncio loop. MAVSDK's ``mavlink_direct`` plugin calls back on its
own thread for every subscribed message; that thread decodes the JSON fields, keeps only the
autopilot this runner locked on (system and component of its first autopilot HEARTBEAT; others
are counted), updates :class:`~mission.vehicle.VehicleState` in place, hands estimator inputs to
the ``sink`` (a bounded queue with a counted drop policy: :mod:`mission.runners.live_wind`), and
wakes the loop at most once per new position. So the loop that sends setpoints and runs the
safety checks stays responsive under CPU load, and every wait it does has a bound.

Messages read: HEARTBEAT (mode, armed, MAV_STATE_EMERGENCY = crashed), EXTENDED_SYS_STATE
(landed state), LOCAL_POSITION_NED (position, velocity; the strategy's observation),
ATTITUDE_QUATERNION (yaw), NAMED_VALUE_FLOAT ``CHEM`` (mg/m^3, 0 below the detection limit),
STATUSTEXT (echoed), WIND_COV; the IMU, attitude and rotor messages go to the sink only.

Conventions: SI, NED (the autopilot's local frame), yaw in rad (degrees on the MAVSDK API),
vehicle time from the messages' time stamps; ``wall`` names wall-clock seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import threading
import time
from collections import Counter, deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from mission.result import MissionError
from mission.runners import ardupilot
from mission.runners.autopilot import find_autopilot
from mission.vehicle import CommandError, VehicleState, Wait
from wire import px4_modes
from wire.names import publish

if TYPE_CHECKING:
    from wire.signing_bridge import SigningBridge

#: Messages the runner subscribes to (the sink's inputs are added by the wind source).
STATE_MESSAGES = ("HEARTBEAT", "EXTENDED_SYS_STATE", "LOCAL_POSITION_NED", "ATTITUDE_QUATERNION",
                  "NAMED_VALUE_FLOAT", "STATUSTEXT", "HOME_POSITION")  # fmt: skip
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_EMERGENCY = 6
#: Mission status queued for the wire at most (the oldest are dropped, counted).
OUTBOX_MAX = 64
#: Sends of a command that timed out, in all (MAVSDK tries four times within about 2 s itself).
COMMAND_ATTEMPTS = 3
#: A jump back of the vehicle clock larger than this is a reboot / clock reset [s].
CLOCK_RESET_S = 5.0

Sink = Callable[[str, dict[str, Any], float, int, int], None]


#: Longest wait for the autopilot's first LOCAL_POSITION_NED after it is healthy [s of vehicle time, and of wall].
POSITION_WAIT_S = 90.0


@dataclass
class LinkConfig:
    """connect: MAVSDK URL; connect_timeout_s / health_timeout_s: wall seconds to wait for a heartbeat /
    for health; link_timeout_s: wall seconds without telemetry that count as a loss; speed_hint: the
    simulator's speed factor (wall-clock waits are divided by it); command_timeout_s: wall seconds
    a command may take; signing_key: a ``wire.signing.SigningKey`` to sign and verify the link with
    (MAVSDK has no signing: the link then runs through ``wire.signing_bridge``), None for none."""

    connect: str
    connect_timeout_s: float = 20.0
    health_timeout_s: float = 30.0
    link_timeout_s: float = 3.0
    speed_hint: float = 1.0
    command_timeout_s: float = 5.0
    signing_key: Any = None


class MavsdkVehicle:
    """See the module docstring. Use as ``async with MavsdkVehicle(cfg, say, sink) as v: ...``."""

    #: The signing bridge while one runs (set in _connect with a signing key; closed and None in close).
    _bridge: SigningBridge | None

    def __init__(self, cfg: LinkConfig, say: Callable[[str], None], sink: Sink | None = None,
                 extra_messages: tuple[str, ...] = ()) -> None:  # fmt: skip
        self.cfg = cfg
        self._say = say
        self.sink = sink
        self.names = STATE_MESSAGES + tuple(n for n in extra_messages if n not in STATE_MESSAGES)
        self.state = VehicleState()
        self.counters: Counter[str] = Counter()
        self.wind_cov: tuple[float, np.ndarray, np.ndarray] | None = None  # (t, wind NED, cov) of WIND_COV
        self.home: dict[str, Any] | None = None  # the last HOME_POSITION's fields (degE7, mm, local m)
        self.target: tuple[int, int] | None = None  # (system, component) locked on
        #: Component whose CHEM readings are used: the first that sent one. PX4 re-publishes every
        #: NAMED_VALUE_FLOAT it receives as its own (a debug value, at a lower rate): that copy is ignored.
        self.chem_component: int | None = None
        self._last_rx = -math.inf  # wall time of the last message from the target
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._new_state: asyncio.Event | None = None
        self._wake_pending = False
        self._outbox: deque[tuple[str, str]] = deque(maxlen=OUTBOX_MAX)
        self._sdk: Any = None
        self._subs: list[tuple[Any, Any]] = []
        self._publisher: asyncio.Task[None] | None = None
        self.drone: Any = None
        self.ardupilot = False  # the autopilot's HEARTBEAT says ArduPilot (modes, streams, failsafe differ)
        self.offboard_active = False  # setpoints streamed since a successful start_offboard
        self._mode_shown = ""

    # ------------------------------------------------------------------ connection
    async def __aenter__(self) -> MavsdkVehicle:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

        self._loop = asyncio.get_running_loop()
        self._new_state = asyncio.Event()
        self._sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        await self._sdk.__aenter__()
        try:
            await self._connect()
        except BaseException:
            await self.__aexit__(None, None, None)
            raise
        return self

    async def __aexit__(self, *exc: object) -> None:
        if (n := self.counters["clock_resets"]) > 1:
            twice = f": two vehicles' streams under system {self.target[0]}?" if n > 2 and self.target else ""
            self.say(f"mission: the vehicle clock went back {n} times in all (said at the first only){twice}")
        if self._publisher is not None:
            self._publisher.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._publisher
        for plugin, handle in self._subs:
            with contextlib.suppress(Exception):
                plugin.unsubscribe_message(handle)
        self._subs = []
        await asyncio.sleep(0)
        bridge = getattr(self, "_bridge", None)
        if bridge is not None:  # stopped before MAVSDK is destroyed: it must not feed a dead core
            bridge.close()
            self._bridge = None
            self.say(f"mission: signing: {bridge.stats()}")
        if self._sdk is not None:
            await self._sdk.__aexit__(None, None, None)
            self._sdk = None

    async def _connect(self) -> None:
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        cfg = self.cfg
        if cfg.signing_key is not None:
            from wire.signing_bridge import SigningBridge

            self._bridge = SigningBridge(self._sdk._mavsdk, cfg.connect, cfg.signing_key).start()
            await self._sdk.add_any_connection("raw://")
            self.say("mission: MAVLink 2 signing on (through windseek's signing bridge: MAVSDK has no signing)")
        else:
            await self._sdk.add_any_connection(cfg.connect)
        drone = await find_autopilot(self._sdk, cfg.connect_timeout_s)
        if drone is None:
            raise MissionError(f"no autopilot heartbeat on {cfg.connect} within {cfg.connect_timeout_s:g} s")
        self.drone = drone
        self.action, self.offb, self.param = ActionAsync(drone), OffboardAsync(drone), ParamAsync(drone)
        self.direct, self.telemetry = MavlinkDirectAsync(drone), TelemetryAsync(drone)
        # The synchronous plugin behind the asyncio wrapper: its callbacks run on MAVSDK's thread,
        # in arrival order across message types, without passing through the event loop.
        plugin = self.direct._plugin
        self._subs = [(plugin, plugin.subscribe_message(n, self._deliver)) for n in self.names]
        st = self.state
        if await self.wait(lambda: st.heartbeat_seq > 0, math.inf, cfg.connect_timeout_s) != Wait.OK:
            raise MissionError("no autopilot HEARTBEAT through mavlink_direct")
        self.say(f"mission: connected to system {self.target[0] if self.target else '?'} on {cfg.connect}")
        if self.ardupilot:
            await ardupilot.request_streams(self)
        await self._healthy()
        # A position estimate needs GNSS lock and the EKF's origin: vehicle time (seconds of it on a real
        # vehicle; ~25 s of ArduCopter SITL's clock after boot), so the bound is in vehicle time, with a wall
        # bound for a simulator that runs slower than real time on a loaded machine (ArduCopter at 0.9x
        # once failed the former 20 s wall bound in benchmarks/ardupilot_search.py).
        bound = max(cfg.connect_timeout_s, POSITION_WAIT_S)
        if await self.wait(lambda: st.pos is not None, POSITION_WAIT_S, bound) != Wait.OK:
            raise MissionError(f"no LOCAL_POSITION_NED from the autopilot within {POSITION_WAIT_S:g} s "
                               "(no position estimate: GNSS lock, the EKF's origin?)")
        self._publisher = asyncio.create_task(self._publish_loop())

    async def _healthy(self) -> None:
        async def ok() -> None:
            async for good in self.telemetry.subscribe_health_all_ok():
                if good:
                    return

        try:
            await asyncio.wait_for(ok(), self.cfg.health_timeout_s)
        except TimeoutError:
            raise MissionError(f"autopilot not healthy within {self.cfg.health_timeout_s:g} s") from None

    def say(self, line: str) -> None:
        self._say(line)

    # ------------------------------------------------------------------ telemetry (MAVSDK's thread)
    def _deliver(self, m: Any, _user: Any = None) -> None:
        try:
            self._on_message(m.message_name, int(m.system_id), int(m.component_id), m.fields_json)
        except Exception:  # noqa: BLE001 - a bad message must never kill MAVSDK's callback thread
            self.counters["rx_bad"] += 1

    def _on_message(self, name: str, sysid: int, compid: int, fields_json: str) -> None:
        f = json.loads(fields_json)
        if name == "HEARTBEAT" and self.target is None and int(f.get("autopilot", 8)) != MAV_AUTOPILOT_INVALID:
            self.target = (sysid, compid)
            self.ardupilot = int(f["autopilot"]) == ardupilot.MAV_AUTOPILOT_ARDUPILOTMEGA
        if self.target is None or sysid != self.target[0]:
            self.counters["rx_other_system"] += 1
            return
        self._last_rx = time.monotonic()
        t = f["time_usec"] * 1e-6 if "time_usec" in f else f["time_boot_ms"] * 1e-3 if "time_boot_ms" in f else math.nan
        st = self.state
        # The vehicle clock: boot time only (time_usec may be UNIX time, e.g. PX4's HOME_POSITION), 0 = unknown.
        if "time_boot_ms" in f and t > 0.0:
            if t < st.t - CLOCK_RESET_S:
                self.counters["clock_resets"] += 1
                st.boots += 1
                if self.counters["clock_resets"] == 1:  # once: two vehicles' streams would say it per message
                    self.say(f"mission: the vehicle clock went back from {st.t:.1f} s to {t:.1f} s (reboot?); "
                             "any further jumps are counted and reported at the end")  # fmt: skip
                st.t = t
            elif not t < st.t or math.isnan(st.t):
                st.t = t
        if name == "NAMED_VALUE_FLOAT" and str(f.get("name", "")).rstrip("\x00") == "CHEM":
            if self.chem_component is None:
                self.chem_component = compid
            elif compid != self.chem_component:
                self.counters["rx_chem_relayed"] += 1
                return
        if self.sink is not None:
            self.sink(name, f, t, sysid, compid)
        if compid != self.target[1] and name not in ("NAMED_VALUE_FLOAT", "WIND_COV", "STATUSTEXT"):
            self.counters["rx_other_component"] += 1
            return
        self._apply(name, f)

    def _apply(self, name: str, f: dict[str, Any]) -> None:
        st = self.state
        if name == "LOCAL_POSITION_NED":
            st.pos = np.array([f["x"], f["y"], f["z"]], dtype=float)
            st.vel = np.array([f["vx"], f["vy"], f["vz"]], dtype=float)
            st.obs_pos, st.obs_vel = st.pos, st.vel
            self._wake()
        elif name == "ATTITUDE_QUATERNION":
            w, x, y, z = f["q1"], f["q2"], f["q3"], f["q4"]
            st.yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        elif name == "NAMED_VALUE_FLOAT" and str(f.get("name", "")).rstrip("\x00") == "CHEM":
            st.chem = float(f["value"])
            st.chem_seq += 1
            t = f.get("time_boot_ms", 0) * 1e-3
            st.chem_t = t if t > 0.0 else math.nan  # the reading's own time (see Observation.chem_t)
        elif name == "HEARTBEAT":
            st.armed = bool(int(f["base_mode"]) & px4_modes.SAFETY_ARMED)
            cm = int(f["custom_mode"])
            if self.ardupilot:  # ArduCopter's mode, by what it does in PX4's names (mission.runners.ardupilot)
                mode, native = ardupilot.loop_mode(cm, self.offboard_active), ardupilot.copter_mode_name(cm)
                shown = mode if mode == native else f"{native} ({mode})"
            else:
                mode = shown = px4_modes.name(cm)
            if mode != st.mode and st.mode:
                self.say(f"mission: autopilot mode {self._mode_shown} -> {shown}")
            st.mode, self._mode_shown = mode, shown
            st.crashed = int(f.get("system_status", 0)) == MAV_STATE_EMERGENCY
            st.heartbeat_seq += 1
            self._wake()
        elif name == "EXTENDED_SYS_STATE":
            st.landed = int(f["landed_state"])
        elif name == "HOME_POSITION":
            self.home = f
        elif name == "STATUSTEXT":
            self.say(f"autopilot: {str(f.get('text', '')).rstrip(chr(0))}")
        elif name == "WIND_COV":
            var_h, var_v = float(f["var_horiz"]), float(f["var_vert"])
            w = np.array([f["wind_x"], f["wind_y"], f["wind_z"]], dtype=float)
            self.wind_cov = (st.t, w, np.diag([var_h / 2, var_h / 2, var_v]))

    def _wake(self) -> None:
        """Set the loop's new-state event, scheduling at most one call at a time (no backlog)."""
        loop, ev = self._loop, self._new_state
        if loop is None or ev is None or self._wake_pending:
            return
        self._wake_pending = True

        def fire() -> None:
            self._wake_pending = False
            ev.set()

        with contextlib.suppress(RuntimeError):  # the loop closed
            loop.call_soon_threadsafe(fire)

    # ------------------------------------------------------------------ waits (the loop)
    def _wall(self, vehicle_s: float) -> float:
        return 2.0 + vehicle_s / max(self.cfg.speed_hint, 1e-3)

    def link_lost(self) -> str | None:
        silent = time.monotonic() - self._last_rx
        if silent > self.cfg.link_timeout_s:
            return (f"no telemetry for {silent:.1f} s (limit {self.cfg.link_timeout_s:g} s): the autopilot's own "
                    "failsafe flies the vehicle (offboard loss: hold; data-link loss: land)")  # fmt: skip
        return None

    async def _settle(self, timeout_s: float) -> None:
        ev = self._new_state
        assert ev is not None
        ev.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(ev.wait(), timeout_s)

    async def wait(self, pred: Callable[[], bool], vehicle_s: float, wall_s: float | None = None) -> Wait:
        st = self.state
        t0 = st.t
        wall_end = time.monotonic() + (self._wall(vehicle_s) if wall_s is None else wall_s)
        while not pred():
            await self._settle(0.2)
            if (math.isfinite(t0) and st.t - t0 > vehicle_s) or time.monotonic() > wall_end:
                return Wait.TIMEOUT
            if self.link_lost() is not None and math.isfinite(self._last_rx):
                return Wait.LINK_LOST
        return Wait.OK

    async def next_tick(self, t_next: float) -> Wait:
        st = self.state
        wall_end = time.monotonic() + min(0.5, self.cfg.link_timeout_s)
        while not st.t >= t_next - 1e-9:
            if self.link_lost() is not None:
                return Wait.LINK_LOST
            if time.monotonic() > wall_end:
                return Wait.TIMEOUT
            await self._settle(0.1)
        return Wait.OK

    async def await_link(self, grace_s: float) -> bool:
        """The link back, then a HEARTBEAT received after it came back (the state is current)."""
        end = time.monotonic() + grace_s
        while time.monotonic() < end and time.monotonic() - self._last_rx > 0.5:
            await asyncio.sleep(0.1)
        if time.monotonic() - self._last_rx > 0.5:
            return False
        seq = self.state.heartbeat_seq
        ok = await self.wait(lambda: self.state.heartbeat_seq > seq, math.inf, 3.0)
        return ok == Wait.OK

    # ------------------------------------------------------------------ commands
    async def _command(self, what: str, make: Callable[[], Awaitable[Any]],
                       lost: tuple[str, ...] = ("TIMEOUT",)) -> None:  # fmt: skip
        """Send a command; one that timed out (no answer: lost on a bad link, after MAVSDK's own four
        tries; ``lost``: the MAVSDK results that mean that) is sent again, :data:`COMMAND_ATTEMPTS` in
        all, unless the link counts as lost. A refusal is never retried. Every command here is
        idempotent (arm, take-off, a mode, a parameter)."""
        for attempt in range(1, COMMAND_ATTEMPTS + 1):
            try:
                await asyncio.wait_for(make(), self.cfg.command_timeout_s)
                return
            except TimeoutError:
                why = f"no answer within {self.cfg.command_timeout_s:g} s"
            except Exception as e:  # noqa: BLE001 - ActionError, OffboardError: the autopilot's reason
                if getattr(getattr(e, "result", None), "name", "") not in lost:
                    raise CommandError(f"{what}: {e}") from None
                why = str(e)
            if attempt == COMMAND_ATTEMPTS or self.link_lost() is not None:
                raise CommandError(f"{what}: {why}" + (f" ({attempt} attempts)" if attempt > 1 else ""))
            self.counters["command_retries"] += 1

    async def arm(self) -> None:
        await self._command("arm", self.action.arm)

    async def takeoff(self, altitude_m: float) -> None:
        # MAVSDK sets MIS_TAKEOFF_ALT; its parameter client's timeout comes back as PARAMETER_ERROR.
        await self._command("set take-off altitude", lambda: self.action.set_takeoff_altitude(float(altitude_m)),
                            ("TIMEOUT", "PARAMETER_ERROR"))
        await self._command("take-off", self.action.takeoff)

    async def start_offboard(self) -> None:
        await self._command("offboard", self.offb.start)
        self.offboard_active = True

    async def stop_offboard(self) -> None:
        self.offboard_active = False
        await self._command("stop offboard", self.offb.stop)

    async def hold(self) -> None:
        await self._command("hold", self.action.hold)

    async def land(self) -> None:
        await self._command("land", self.action.land)

    def send_setpoint(self, pos: np.ndarray | None, vel: np.ndarray | None, yaw: float | None) -> None:
        """Through the synchronous plugin: the call only queues the message in MAVSDK (no await), so
        a strategy tick never waits on the loop; MAVSDK repeats the last setpoint at 20 Hz."""
        from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw

        st, plugin = self.state, self.offb._plugin
        yaw_deg = math.degrees(st.yaw if yaw is None else yaw)
        try:
            if pos is not None and vel is not None:
                plugin.set_position_velocity_ned(PositionNedYaw(*map(float, pos), yaw_deg),
                                                 VelocityNedYaw(*map(float, vel), yaw_deg))  # fmt: skip
            elif pos is not None:
                plugin.set_position_ned(PositionNedYaw(*map(float, pos), yaw_deg))
            elif vel is not None:
                plugin.set_velocity_ned(VelocityNedYaw(*map(float, vel), yaw_deg))
        except Exception as e:  # noqa: BLE001 - OffboardError or a closed link
            raise CommandError(f"offboard setpoint: {e}") from None

    # ------------------------------------------------------------------ publishing
    def publish(self, pairs: list[tuple[str, str]]) -> None:
        if len(self._outbox) + len(pairs) > OUTBOX_MAX:
            self.counters["outbox_dropped"] += len(self._outbox) + len(pairs) - OUTBOX_MAX
        self._outbox.extend(pairs)

    async def _publish_loop(self) -> None:
        """Send the queued mission status (STATUSTEXT states, the declaration) over mavlink_direct;
        a failed send is said once and never stops the mission."""
        failed = False
        while True:
            await asyncio.sleep(0.05)
            if not self._outbox:
                continue
            pairs = list(self._outbox)
            self._outbox.clear()
            try:
                await asyncio.wait_for(publish(self.direct, pairs), self.cfg.command_timeout_s)
            except Exception as e:  # noqa: BLE001 - MavlinkDirectError, a closed link, a timeout
                self.counters["publish_failed"] += 1
                if not failed:
                    failed = True
                    self.say(f"mission: could not publish {pairs[0][0]} over MAVLink ({e}); the mission goes on")
