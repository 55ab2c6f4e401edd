"""The SITL link: a :class:`~sitl.simulation.Simulation` behind a MAVLink endpoint, paced to the wall clock.

One thread, one loop: advance the simulation by one chunk (10 ms of simulation time) in
lockstep, send what is due, then wait on the sockets until the wall-clock instant at which the
next chunk is due (``sim time / speed``), handling whatever arrives. Commands therefore act
between two chunks, never inside the physics, and the simulation stays deterministic for a
given sequence of inputs. When the machine cannot keep up, the loop runs the chunks back to
back (still servicing the sockets between them); a lag over ``MAX_LAG_S`` of simulation time
is forgiven (the clock is re-anchored) and counted in ``counters["overruns"]``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any

from sitl.autopilot.flight_modes import ItemKind, Mode
from sitl.link.commands import CommandHandler, autopilot_version
from sitl.link.datalink import DataLinkFailsafe
from sitl.link.endpoint import Endpoint, Link, targets_us
from sitl.link.ftp import FtpServer
from sitl.link.geofence import Geofence
from sitl.link.mission_protocol import MissionProtocol
from sitl.link.offboard import OffboardHandler
from sitl.link.params import ParamProtocol, ParamTable
from sitl.link.port import AutopilotPort
from sitl.link.sim_params import WorldKnobs, sitl_parameters
from sitl.link.streams import StreamScheduler
from sitl.link.telemetry import Telemetry
from sitl.link.transports import Transport
from sitl.simulation import Simulation
from wire.dialect import mavlink as mav
from wire.signing import SigningKey

log = logging.getLogger(__name__)

CHUNK_S = 0.01
MAX_LAG_S = 0.5


class SitlLink:
    """Simulation + endpoint + protocol handlers + pacing loop.

    Args:
        sim: the simulation (created with ``autostart_route=False``).
        transports: the byte pipes (UDP, TCP server, serial), all served at once.
        speed: simulation seconds per wall-clock second (> 0).
        true_wind_hz: rate of the simulation-only TRUEW* debug values (0 = off).
        signing_key: MAVLink 2 signing on every link (:mod:`wire.signing`); None: no signing.
        allow_sim_params: the simulation knobs (``SIM_*``) may be set over MAVLink; otherwise a
            PARAM_SET of one is refused (PARAM_ERROR PERMISSION_DENIED) and the value stays.
    """

    #: Why the background loop stopped (set by :meth:`start`: None while it runs or stopped cleanly).
    error: Exception | None

    def __init__(self, sim: Simulation, transports: list[Transport], speed: float = 1.0,
                 true_wind_hz: float = 5.0, signing_key: SigningKey | None = None,
                 allow_sim_params: bool = False) -> None:  # fmt: skip
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed {speed}: must be a finite number > 0")
        self.sim = sim
        self.allow_sim_params = bool(allow_sim_params)
        self.endpoint = Endpoint(transports, signing_key)
        self.telemetry = Telemetry(sim)
        self.streams = StreamScheduler(self.telemetry, true_wind_hz)
        self.geofence = Geofence()
        sim.step_hooks.append(self.geofence.on_mode_tick)
        ep = self.endpoint
        self.port = AutopilotPort(fc=sim.fc, clock=lambda: sim.t, position=lambda: sim.position,
                                  attitude=lambda: sim.quaternion, home=sim.scenario.sensors.home,
                                  mission_changed=self.mission_changed,
                                  mode_commanded=self.telemetry.end_mission_landing)  # fmt: skip
        self.commands = CommandHandler(ep, self.port, self.streams)
        self.missions = MissionProtocol(ep, self.port, self.geofence, self.telemetry.mission_current)
        self.commands.land_start_index = self.missions.land_start_index
        self.offboard = OffboardHandler(ep, self.port)
        self.knobs = WorldKnobs(sim.world)
        self.params = ParamTable(sitl_parameters(sim.autopilot, self.geofence, self.knobs,
                                                 lambda: self.speed, self.set_speed, self._sim_lock))  # fmt: skip
        self.param_protocol = ParamProtocol(ep, self.params)
        self.ftp = FtpServer(ep)  # answers MAVProxy's / QGC's FTP at once, as PX4 (read-only, empty tree)
        # NAV_DLL_ACT: land when the ground link's heartbeats stop.
        self.datalink = DataLinkFailsafe(ep, sim.fc, lambda: sim.t, self.params)
        sim.step_hooks.append(self.datalink.on_mode_tick)
        ep.handlers["HEARTBEAT"] = self.on_heartbeat
        self._greeted: set[tuple] = set()
        ep.handlers["TIMESYNC"] = self.on_timesync
        ep.handlers["PING"] = self.on_ping
        self.speed = float(speed)
        self._chunk_ticks = max(1, round(CHUNK_S / sim.dt))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._wall0 = 0.0
        self._sim0 = 0.0
        self._last_mode = (self.telemetry.reported_mode(), sim.fc.armed)
        self._last_index = sim.fc.mission_index
        self.chunks = 0
        self.lag_max_s = 0.0

    def _sim_lock(self) -> str | None:
        return None if self.allow_sim_params else "simulation knobs need --allow-sim-params"

    @property
    def counters(self) -> dict[str, int]:
        return self.endpoint.counters

    def home_amsl(self) -> float:
        """Home altitude AMSL, m."""
        return self.port.home_amsl()

    def set_speed(self, speed: float) -> None:
        """Change the speed factor now (re-anchors the wall clock, so there is no jump)."""
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"speed {speed}: must be > 0")
        self._wall0 = time.monotonic()
        self._sim0 = self.sim.t
        self.speed = float(speed)

    def mission_changed(self) -> None:
        self.telemetry.rtl_handover = None
        self._last_index = -1  # announce MISSION_CURRENT at the next chunk

    # ------------------------------------------------------------------ small handlers
    def on_timesync(self, msg: Any, link: Link) -> None:
        if msg.tc1 == 0:  # a request: answer with our (simulation) clock
            self.endpoint.reply(mav.MAVLink_timesync_message(int(self.sim.t * 1e9), msg.ts1), link)

    def on_heartbeat(self, msg: Any, link: Link) -> None:
        """A ground station's first HEARTBEAT gets AUTOPILOT_VERSION unasked. PX4 sends it blindly when a
        serial link starts; clients that ask only once per heartbeat (dronekit) would otherwise read their
        version as None when a short parameter download ends before the answer."""
        if getattr(msg, "type", None) != mav.MAV_TYPE_GCS or not self.endpoint.authentic(msg):
            return
        key = (link.index, link.rx_source, msg.get_srcSystem(), msg.get_srcComponent())
        if key in self._greeted:
            return
        if len(self._greeted) >= 256:  # bounded: a flood of forged senders cannot grow it
            self._greeted.clear()
            self.counters["greeted_reset"] += 1
        self._greeted.add(key)
        self.endpoint.reply(autopilot_version(), link)

    def on_ping(self, msg: Any, link: Link) -> None:
        if msg.target_system == 0 and msg.target_component == 0:
            self.endpoint.reply(
                mav.MAVLink_ping_message(msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent()), link
            )
        elif not targets_us(msg):
            return

    # ------------------------------------------------------------------ loop
    def advance(self) -> None:
        """One chunk of simulation, then everything it produced goes out."""
        sim = self.sim
        fc = sim.fc
        sim.step(self._chunk_ticks)
        self.chunks += 1
        samples = sim.drain()
        tel = self.telemetry
        tel.ingest(samples)
        tel.update_battery()
        out = self.streams.due(sim.t, samples)
        if fc.events:
            for ev in fc.events:
                out.append(mav.MAVLink_statustext_message(ev.severity, ev.text.encode()[:50]))
            fc.events.clear()
        if fc.mission_reached:
            for i in fc.mission_reached:
                kind = fc.mission[i].kind if i < len(fc.mission) else None
                # PX4 hands a NAV_RETURN_TO_LAUNCH item over to RTL mode without reporting it
                # reached, and MAVSDK's is_mission_finished() counts on exactly that.
                if kind == ItemKind.RTL:
                    tel.rtl_handover = i
                    self._last_index = -1  # announce the completed state now
                    continue
                if kind == ItemKind.LAND:
                    # PX4 flies a land item inside Mission mode and reports it reached on touchdown.
                    tel.mission_landing = i
                    self._last_index = -1
                    continue
                out.append(mav.MAVLink_mission_item_reached_message(i))
            fc.mission_reached.clear()
        out.extend(tel.mission_landing_step())
        # An extra HEARTBEAT on a change of the mode on the wire or of arming lets clients see it at once.
        # Judged after the mission-landing bookkeeping above: a mission's LAND item switches the built-in
        # autopilot to LAND in this chunk, but PX4 flies it in AUTO.MISSION (MissionBase handles
        # NAV_CMD_LAND itself), so the wire stays in MISSION; a HEARTBEAT built before would say
        # AUTO.LAND once and AUTO.MISSION 70 ms later (MAVProxy: "Mode LAND", then "Mode MISSION").
        state = (tel.reported_mode(), fc.armed)
        if state != self._last_mode:
            self._last_mode = state
            out.extend(tel.heartbeat())
        if fc.mission_index != self._last_index:
            self._last_index = fc.mission_index
            out.extend(tel.mission_current())
        self.endpoint.send_many(out)

    def serve(self, duration_s: float | None = None) -> None:
        """Run paced until :meth:`stop` (or for ``duration_s`` of simulation time)."""
        sim = self.sim
        self._wall0 = time.monotonic()
        self._sim0 = sim.t
        t_end = math.inf if duration_s is None else sim.t + duration_s
        chunk = self._chunk_ticks * sim.dt
        while not self._stop.is_set() and sim.t < t_end - 1e-9:
            now = time.monotonic()
            due = self._sim0 + (now - self._wall0) * self.speed
            lag = due - sim.t
            if lag >= chunk - 1e-9:
                self.lag_max_s = max(self.lag_max_s, lag)
                if lag > MAX_LAG_S:
                    self.counters["overruns"] += 1
                    self._wall0 = now
                    self._sim0 = sim.t
                self.advance()
                self.endpoint.poll(0.0)
            else:
                wait = (sim.t + chunk - self._sim0) / self.speed + self._wall0 - now
                self.endpoint.poll(min(max(wait, 0.0), 0.05))
            self.missions.tick()

    def _serve_logged(self) -> None:
        try:
            self.serve()
        except Exception as e:  # keep the reason: a silent dead thread looks like a lost link
            log.exception("SITL link loop stopped")
            self.error = e

    def start(self) -> SitlLink:
        """Serve in a background thread (tests, embedding); a crash is kept in :attr:`error`."""
        self._stop.clear()
        self.error = None
        self._thread = threading.Thread(target=self._serve_logged, name="sitl-link", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None

    def close(self) -> None:
        self.stop()
        self.endpoint.close()

    @property
    def mode(self) -> Mode:
        return self.sim.fc.mode
