"""What ``windseek sitl`` does with the wire besides being an autopilot: tlog, forwarding, Rerun, truth summary.

Four optional attachments to a :class:`~sitl.link.runner.SitlLink`, each one ``attach`` call,
all run in the link's own thread (the endpoint's ``rx_hooks`` and the simulation's
``step_hooks``), so nothing here needs a lock:

- :class:`TlogWriter` (``--tlog PATH``): every MAVLink frame sent and received, in the standard
  ``.tlog`` format (per frame an 8-byte big-endian time stamp in microseconds, then the frame
  as on the wire). The time stamp is **wall-clock UNIX time** (what MAVProxy and QGroundControl
  write, so MAVExplorer and ``mavlogdump.py`` show real dates); the simulation time is inside the
  messages (``time_boot_ms`` / ``time_usec``). Frames sent to several links are logged once.
- :class:`Forwarder` (``--forward``): like PX4 with ``MAV_X_FORWARD`` on every link: a frame
  received on one link that is not addressed to the autopilot (system 1, component 1) goes
  out unchanged on every other link and to the other peers of the same UDP link, so the
  mission and a ground station see the estimator's WIND_COV and the mission's status.
- :class:`WireRecorder` (``--rrd PATH``): the simulation's truth through
  :func:`recording.sim_hook.record_simulation`, plus what only the wire knows: WIND_COV
  (estimate, +-2 sigma band, speed and from-direction raw and low-passed, the estimate arrow at
  the vehicle), the mission's strategy states and declared source (:mod:`wire.names`: the
  phases, path colours and events), the geofence box given on the command line, and at close a
  run summary from the truth.
- :class:`TruthSummary` (``--exit-summary PATH``): a JSON file written at shutdown with the
  figures only the simulator can compute: RMSE of the received WIND_COV estimates against the
  true wind at the vehicle at the estimate's time stamp (airborne samples only), the true
  source(s), the declared source and its horizontal error, path length, final vehicle state.

Conventions: SI, NED, wind = air-mass velocity NED; all times here are simulation seconds
except the tlog stamps.
"""

from __future__ import annotations

import bisect
import json
import math
import struct
import time
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sitl.link.endpoint import COMPONENT_ID, SYSTEM_ID, Link
from sitl.link.transports import UdpTransport
from wire.jsonsafe import json_safe
from wire.names import ESTIMATOR_COMPONENT, MISSION_COMPONENT, SRC_CONF, SRC_NAMES, STATE_PREFIX

if TYPE_CHECKING:
    from recording.recorder import RunRecorder
    from recording.summary import RunSummary
    from sitl.link.runner import SitlLink
    from sitl.simulation import Simulation

#: Airborne = true height above the start point over this [m] (wind RMSE is scored only then).
AIRBORNE_M = 1.0


def _name(msg: Any) -> str:
    return str(getattr(msg, "name", "")).rstrip("\x00")


class TlogWriter:
    """Writes every frame the link sends and receives to a ``.tlog`` (see the module docstring)."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self.frames = 0

    def write(self, frame: bytes, t_unix_s: float | None = None) -> None:
        if self._f.closed:
            return
        ts = int((time.time() if t_unix_s is None else t_unix_s) * 1e6)
        self._f.write(struct.pack(">Q", ts) + bytes(frame))
        self.frames += 1

    def attach(self, link: SitlLink) -> TlogWriter:
        ep = link.endpoint

        def received(msg: Any, lk: Link) -> None:  # msg: a parsed pymavlink message
            self.write(msg.get_msgbuf())

        ep.tx_hooks.append(self.write)  # every outgoing frame is packed exactly once, in Endpoint.encode
        ep.rx_hooks.append(received)
        return self

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()


def addressed_to_autopilot(msg: Any) -> bool:
    """True for a message addressed to system 1, component 1 (or to system 1 with no component)."""
    ts = getattr(msg, "target_system", None)
    if ts is None or ts != SYSTEM_ID:
        return False
    return getattr(msg, "target_component", COMPONENT_ID) in (COMPONENT_ID,)


class Forwarder:
    """PX4-style forwarding of frames not addressed to the autopilot to every other link and peer."""

    def __init__(self, link: SitlLink) -> None:
        self.link = link
        self.forwarded = 0
        link.endpoint.rx_hooks.append(self.on_message)

    def on_message(self, msg: Any, src: Link) -> None:
        if addressed_to_autopilot(msg):
            return
        frame = msg.get_msgbuf()
        for lk in self.link.endpoint.links:
            t = lk.transport
            if lk is not src:
                t.write(frame)
            elif isinstance(t, UdpTransport) and src.rx_source is not None:
                t.write_except(frame, src.rx_source)
        self.forwarded += 1
        self.link.counters["forwarded"] += 1


class _Truth:
    """Recent true wind at the vehicle (simulation time, NED m/s), for scoring late estimates."""

    def __init__(self, keep_s: float = 60.0, rate_hz: float = 50.0) -> None:
        n = int(keep_s * rate_hz)
        self.t: deque[float] = deque(maxlen=n)
        self.w: deque[np.ndarray] = deque(maxlen=n)
        self.h: deque[float] = deque(maxlen=n)

    def add(self, t: float, wind: np.ndarray, height_m: float) -> None:
        self.t.append(t)
        self.w.append(np.array(wind, dtype=float))
        self.h.append(height_m)

    def at(self, t: float) -> tuple[np.ndarray, float] | None:
        """True wind and height at ``t`` (nearest recorded sample within 0.1 s), or None."""
        if not self.t:
            return None
        ts = self.t
        i = bisect.bisect_left(ts, t)
        best = None
        for j in (i - 1, i):
            if 0 <= j < len(ts) and (best is None or abs(ts[j] - t) < abs(ts[best] - t)):
                best = j
        if best is None or abs(ts[best] - t) > 0.1:
            return None
        return self.w[best], self.h[best]


class TruthSummary:
    """Scores WIND_COV estimates and the declared source against the simulation's truth."""

    def __init__(self, link: SitlLink, path: Path | str) -> None:
        self.link = link
        self.path = Path(path)
        self.truth = _Truth(rate_hz=link.sim.scenario.mode_rate_hz)
        self.err2 = np.zeros(3)
        self.n = 0
        self.n_received = 0
        self.last_estimate: list[float] | None = None
        self.path_m = 0.0
        self._prev: np.ndarray | None = None
        self.declared: dict[str, float] = {}
        self.declaration: dict[str, Any] | None = None
        self.statustexts = 0
        link.sim.step_hooks.append(self.on_tick)
        link.endpoint.rx_hooks.append(self.on_message)

    def on_tick(self, s: Simulation) -> None:
        pos = np.array(s.x[0:3], dtype=float)
        self.truth.add(s.t, s.wind_at_vehicle, -float(pos[2]))
        if self._prev is not None:
            self.path_m += float(np.linalg.norm(pos - self._prev))
        self._prev = pos

    def on_message(self, msg: Any, lk: Link) -> None:
        mtype = msg.get_type()
        if mtype == "WIND_COV":
            self.n_received += 1
            w = np.array([msg.wind_x, msg.wind_y, msg.wind_z], dtype=float)
            self.last_estimate = [round(float(v), 3) for v in w]
            tr = self.truth.at(msg.time_usec * 1e-6)
            if tr is not None and tr[1] > AIRBORNE_M and np.all(np.isfinite(w)):
                self.err2 += (w - tr[0]) ** 2
                self.n += 1
        elif mtype == "NAMED_VALUE_FLOAT":
            name = _name(msg)
            if name in SRC_NAMES:
                self.declared[name] = float(msg.value)
            elif name == SRC_CONF and all(n in self.declared for n in SRC_NAMES):
                self.declaration = {"declared_ned": [self.declared[n] for n in SRC_NAMES],
                                    "confidence": float(msg.value), "t_s": msg.time_boot_ms * 1e-3}  # fmt: skip
        elif mtype == "STATUSTEXT":
            self.statustexts += 1

    def true_sources(self) -> list[list[float]]:
        chem = self.link.sim.chem
        if chem is None:
            return []
        return [[float(v) for v in p] for p in chem.sources_ned]

    def to_dict(self) -> dict[str, Any]:
        sim = self.link.sim
        rmse = np.sqrt(self.err2 / self.n) if self.n else np.full(3, math.nan)
        d: dict[str, Any] = {
            "scenario": sim.scenario.name,
            "sim_time_s": round(sim.t, 3),
            "wind_estimates_received": self.n_received,
            "wind_estimates_scored": self.n,
            "wind_rmse_ned_m_s": [round(float(v), 3) for v in rmse],
            "wind_rmse_horizontal_m_s": round(float(math.hypot(rmse[0], rmse[1])), 3),
            "wind_last_estimate_ned_m_s": self.last_estimate,
            "wind_true_at_vehicle_ned_m_s": [round(float(v), 3) for v in sim.wind_at_vehicle],
            "true_sources_ned_m": self.true_sources(),
            "declared": self.declaration,
            "declared_error_horizontal_m": None,
            "path_length_m": round(self.path_m, 2),
            "final_position_ned_m": [round(float(v), 3) for v in sim.x[0:3]],
            "final_velocity_ned_m_s": [round(float(v), 3) for v in sim.x[3:6]],
            "final_mode": getattr(sim.fc.mode, "name", str(sim.fc.mode)),
            "armed": bool(sim.fc.armed),
            "crashed": bool(sim.crashed),
            "forwarded_messages": int(self.link.counters.get("forwarded", 0)),
            # Counts only: the key itself is never written anywhere.
            "signing": ({"rx_unauthenticated": int(self.link.counters.get("rx_unauthenticated", 0)),
                         **self.link.endpoint.signing_counts()} if self.link.endpoint.signing_on else None),
            "statustexts_received": self.statustexts,
        }
        srcs = d["true_sources_ned_m"]
        if self.declaration is not None and srcs:
            dn = np.array(self.declaration["declared_ned"][:2])
            d["declared_error_horizontal_m"] = round(min(float(np.hypot(*(dn - np.array(s[:2])))) for s in srcs), 3)
        return json_safe(d)

    def write(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.write_text(json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n")

    def close(self) -> None:
        """Write the summary (at shutdown)."""
        self.write()



class WireRecorder:
    """The simulation's truth and what arrives on the wire (WIND_COV, mission status) into one ``.rrd``.

    The mission's STATUSTEXT states and its declaration (:mod:`wire.names`) drive the recording's
    phases, path colours and events exactly as an in-process trial's do; WIND_COV gives the wind
    estimate (with its +-2 sigma band) and the filtered direction. At close it writes a run summary
    from what the SITL knows (truth, the wire); ``windseek demo`` later completes it with the
    mission's own result (:mod:`recording.finalize`).

    Args:
        link: the SITL link (its thread runs every hook).
        path: the ``.rrd`` file.
        strategy: recording label (the mission's strategy, if known).
        geofence_ned: (min corner, max corner) of the mission's geofence box [m, NED], drawn static.
        field_altitude_m: height of the urban wind field's horizontal slice [m above the ground]
            (None: the scenario's take-off altitude).
        filter_cutoff_hz: cutoff of the first-order low-pass giving the "filtered" wind direction
            from the received estimates [Hz].
    """

    def __init__(self, link: SitlLink, path: Path | str, strategy: str | None = None,
                 geofence_ned: tuple[list[float], list[float]] | None = None,
                 filter_cutoff_hz: float = 0.05, field_altitude_m: float | None = None) -> None:  # fmt: skip
        from recording.recorder import RunRecorder
        from recording.sim_hook import record_simulation
        from recording.stream import CpuMeter
        from recording.tally import FlightTally

        sim = link.sim
        self.link = link
        self.strategy = strategy
        # Rates and sends chosen so the recording costs the SITL under 10 % of its CPU
        # (benchmarks/recording_cost.py): pose and true series at 5 Hz (the estimate at its own
        # rate), plume slices every 5 s, the buffered rows sent every 15 s of simulation (a live
        # viewer lags by that much).
        self.meter = CpuMeter()  # what recording costs this process: the recording_cost property
        self.t0 = sim.t
        self.rec: RunRecorder = self.meter(lambda: RunRecorder(path, scenario=sim.scenario.name, strategy=strategy,
                                                               seed=sim.seed, series_flush_s=15.0))  # fmt: skip
        if geofence_ned is not None:
            self.rec.geofence(*geofence_ned)
        # Metered: an urban scenario's buildings and wind field are logged here, once.
        self.meter(lambda: record_simulation(sim, self.rec, vehicle_hz=5.0, series_hz=5.0, slice_hz=0.2,
                                             field_altitude_m=field_altitude_m, meter=self.meter))  # fmt: skip
        self.tally = FlightTally([] if sim.chem is None else sim.chem.sources_ned)
        # The path (t, n, e, d) at every mode tick of the last 60 s: an estimate is scored against the
        # wind field at its nearest tick's time and position (estimates arrive late). The field is
        # evaluated only then, not every tick; positions are kept exactly because the turbulent field
        # changes by ~0.1 m/s over 0.1 m (an interpolated position would score the estimate wrongly).
        rate = sim.scenario.mode_rate_hz
        self.track: deque[tuple[float, float, float, float]] = deque(maxlen=max(1, int(60.0 * rate)))
        self.tally_every = max(1, round(rate / 10.0))  # the path length and phases' tally at 10 Hz
        self._k = -1
        self.tau_s = 1.0 / (2.0 * math.pi * filter_cutoff_hz)
        self._filt: np.ndarray | None = None
        self._t_filt = 0.0
        self.estimates = 0
        self.wind_from: tuple[int, int] | None = None
        sim.step_hooks.append(lambda s: self.meter(self.on_tick, s))
        link.endpoint.rx_hooks.append(lambda msg, lk: self.meter(self.on_message, msg, lk))

    def on_tick(self, s: Simulation) -> None:
        """The vehicle's position at every mode tick (the true-wind lookups); the tally at 10 Hz."""
        x = s.x
        self.track.append((s.t, float(x[0]), float(x[1]), float(x[2])))
        self._k += 1
        if self._k % self.tally_every == 0:
            ph = self.rec.phases
            self.tally.position(x[0:3], ph.armed, ph.searching, ph.declared)

    def true_wind(self, t: float) -> tuple[np.ndarray, float] | None:
        """True wind [m/s NED] at the vehicle at the mode tick nearest to time ``t`` [s] and the height
        then [m], or None when no kept tick is within 0.1 s."""
        tr = self.track
        if not tr:
            return None
        i = bisect.bisect_left(tr, (t,))
        near = min((tr[j] for j in (i - 1, i) if 0 <= j < len(tr)), key=lambda r: abs(r[0] - t))
        if abs(near[0] - t) > 0.1:
            return None
        pos = np.array(near[1:])
        return np.asarray(self.link.sim.wind.velocity(near[0], pos), dtype=float), -float(pos[2])

    def on_message(self, msg: Any, lk: Link) -> None:
        mtype = msg.get_type()
        sim, rec = self.link.sim, self.rec
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if mtype == "WIND_COV":
            t = msg.time_usec * 1e-6
            wx, wy, wz = float(msg.wind_x), float(msg.wind_y), float(msg.wind_z)
            if not (math.isfinite(wx) and math.isfinite(wy) and math.isfinite(wz)):
                return
            w = np.array([wx, wy, wz])
            self.estimates += 1
            self.wind_from = src
            sh = math.sqrt(max(float(msg.var_horiz), 0.0) / 2.0)
            sv = math.sqrt(max(float(msg.var_vert), 0.0))
            rec.wind(t, est_ned=w, sigma_ned=[sh, sh, sv])
            rec.wind_arrows(t, sim.x[0:3], None, w)
            if self._filt is None:
                self._filt = w[:2].copy()
            else:
                a = min(1.0, max(0.0, t - self._t_filt) / self.tau_s)
                self._filt += a * (w[:2] - self._filt)
            self._t_filt = t
            fn, fe = float(self._filt[0]), float(self._filt[1])
            # From-directions with math (vehicle.frames.from_direction_deg's numpy costs ~40 us a call).
            rec.wind_speed_dir(t, math.hypot(wx, wy), math.degrees(math.atan2(-wy, -wx)) % 360.0,
                               math.hypot(fn, fe), math.degrees(math.atan2(-fe, -fn)) % 360.0)  # fmt: skip
            tr = self.true_wind(t) if self.estimates % 2 == 0 else None  # every other one: the field is costly
            if tr is not None:
                self.tally.wind(w, tr[0], tr[1])
        elif mtype == "STATUSTEXT":
            if src == (SYSTEM_ID, COMPONENT_ID):
                return
            text = str(msg.text).rstrip("\x00")
            who = {MISSION_COMPONENT: "mission", ESTIMATOR_COMPONENT: "estimator"}.get(src[1], f"{src[0]}:{src[1]}")
            if text.startswith(STATE_PREFIX):
                who = "mission"
            rec.mission_statustext(sim.t, text, who, "WARN" if msg.severity <= 4 else "INFO")
        elif mtype == "NAMED_VALUE_FLOAT":
            name = _name(msg)
            if name in SRC_NAMES or name == SRC_CONF:
                # The mission stamps its declaration with its own tick time (vehicle time).
                rec.mission_named_value(msg.time_boot_ms * 1e-3, name, float(msg.value))

    def summary(self) -> RunSummary:
        """What the SITL knows of the run: truth, the wire's declaration, the phases it saw."""
        from recording.summary import RunSummary

        rec, ph = self.rec, self.rec.phases
        src = "none received" if self.wind_from is None else \
            f"WIND_COV from system {self.wind_from[0]} component {self.wind_from[1]} ({self.estimates} received)"
        s = RunSummary(kind="windseek sitl (truth and the wire)", scenario=self.link.sim.scenario.name,
                       strategy=self.strategy, seed=self.link.sim.seed, wind_source=src)  # fmt: skip
        if math.isfinite(ph.t_declared) and math.isfinite(ph.t_arm):
            s.time_to_declaration_s = round(ph.t_declared - ph.t_arm, 2)
        if math.isfinite(ph.t_arm):
            end = ph.t_disarm if math.isfinite(ph.t_disarm) else self.link.sim.t
            s.mission_time_s = round(end - ph.t_arm, 2)
        if rec.declaration is None and self.strategy:
            s.cause = "no declaration received"
        self.tally.fill(s)
        return s

    def close(self) -> None:
        rec = self.rec
        self.meter(lambda: rec.summary(self.summary()))
        self.meter(rec.close, lambda: {"sim_s": round(self.link.sim.t - self.t0, 3), **self.meter.report(rec)})


__all__ = ["AIRBORNE_M", "Forwarder", "TlogWriter", "TruthSummary", "WireRecorder", "addressed_to_autopilot"]
