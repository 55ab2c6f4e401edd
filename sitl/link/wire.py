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
  the vehicle), the mission's STATUSTEXT lines and declared source (:mod:`wire.names`),
  the geofence box given on the command line, the chemical detection threshold.
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
from vehicle.frames import from_direction_deg
from wire.jsonsafe import json_safe
from wire.names import MISSION_COMPONENT, SRC_CONF, SRC_NAMES, STATE_PREFIX

if TYPE_CHECKING:
    from recording.rerun_log import RunRecorder
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
        encode = ep.encode

        def tapped(msg: object) -> bytes:
            buf = encode(msg)
            self.write(buf)
            return buf

        ep.encode = tapped  # every outgoing frame is packed exactly once, here
        ep.rx_hooks.append(lambda msg, lk: self.write(msg.get_msgbuf()))
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
    """The simulation's truth and the wire's WIND_COV / mission status into one ``.rrd``.

    Args:
        link: the SITL link (its thread runs every hook).
        path: the ``.rrd`` file.
        strategy: recording label (the mission's strategy, if known).
        geofence_ned: (min corner, max corner) of the mission's geofence box [m, NED], drawn static.
        filter_cutoff_hz: cutoff of the first-order low-pass giving the "filtered" wind speed and
            direction from the received estimates [Hz].
    """

    def __init__(self, link: SitlLink, path: Path | str, strategy: str | None = None,
                 geofence_ned: tuple[list[float], list[float]] | None = None,
                 filter_cutoff_hz: float = 0.05) -> None:  # fmt: skip
        from recording.rerun_log import RunRecorder
        from recording.sim_hook import record_simulation

        sim = link.sim
        self.link = link
        self.rec: RunRecorder = RunRecorder(path, scenario=sim.scenario.name, strategy=strategy, seed=sim.seed)
        record_simulation(sim, self.rec)
        if geofence_ned is not None:
            self.rec.geofence(*geofence_ned)
        self.threshold = None if sim.chem is None else sim.chem.sensor.config.detection_limit_mg_m3
        self.tau_s = 1.0 / (2.0 * math.pi * filter_cutoff_hz)
        self._filt: np.ndarray | None = None
        self._t_filt = 0.0
        self._t_thresh = -math.inf
        self._src: dict[str, float] = {}
        self.estimates = 0
        link.endpoint.rx_hooks.append(self.on_message)

    def on_message(self, msg: Any, lk: Link) -> None:
        mtype = msg.get_type()
        sim = self.link.sim
        if mtype == "WIND_COV":
            t = msg.time_usec * 1e-6
            w = np.array([msg.wind_x, msg.wind_y, msg.wind_z], dtype=float)
            if not np.all(np.isfinite(w)):
                return
            self.estimates += 1
            sh = math.sqrt(max(float(msg.var_horiz), 0.0) / 2.0)
            sv = math.sqrt(max(float(msg.var_vert), 0.0))
            self.rec.wind(t, est_ned=w, sigma_ned=[sh, sh, sv])
            self.rec.wind_arrows(t, sim.x[0:3], None, w)
            if self._filt is None:
                self._filt = w[:2].copy()
            else:
                a = min(1.0, max(0.0, t - self._t_filt) / self.tau_s)
                self._filt += a * (w[:2] - self._filt)
            self._t_filt = t
            speed = math.hypot(w[0], w[1])
            f = self._filt
            self.rec.wind_speed_dir(t, speed, float(from_direction_deg(w[0], w[1])),
                                    math.hypot(f[0], f[1]), float(from_direction_deg(f[0], f[1])))  # fmt: skip
            if self.threshold is not None and t - self._t_thresh >= 1.0:
                self._t_thresh = t
                self.rec.chem(t, math.nan, self.threshold)
        elif mtype == "STATUSTEXT":
            if msg.get_srcComponent() == COMPONENT_ID and msg.get_srcSystem() == SYSTEM_ID:
                return
            text = str(msg.text).rstrip("\x00")
            mission = text.startswith(STATE_PREFIX) or msg.get_srcComponent() == MISSION_COMPONENT
            channel = "mission" if mission else "wire"
            level = "WARN" if msg.severity <= 4 else "INFO"
            self.rec.text(sim.t, f"[{msg.get_srcSystem()}:{msg.get_srcComponent()}] {text}", level, channel)
        elif mtype == "NAMED_VALUE_FLOAT":
            name = _name(msg)
            if name in SRC_NAMES:
                self._src[name] = float(msg.value)
            elif name == SRC_CONF and all(n in self._src for n in SRC_NAMES):
                true = [] if sim.chem is None else sim.chem.sources_ned.tolist()
                self.rec.sources(true, [self._src[n] for n in SRC_NAMES], float(msg.value), t=sim.t)
                self.rec.text(sim.t, "source declared at N {:.1f} E {:.1f} D {:.1f} m ({:.0f}%)".format(
                    *(self._src[n] for n in SRC_NAMES), 100 * float(msg.value)), "INFO", "mission")

    def close(self) -> None:
        self.rec.close()


__all__ = ["AIRBORNE_M", "Forwarder", "TlogWriter", "TruthSummary", "WireRecorder", "addressed_to_autopilot"]
