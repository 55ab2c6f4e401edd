"""The mission's side of a run in a ``.rrd``: what the strategy believed and what the mission sent.

``windseek mission --rrd PATH`` builds a :class:`MissionRecorder` and hands its :meth:`~MissionRecorder.attach`
to the MAVSDK runner (``MissionConfig.observe``), which calls it with the mission loop once the loop
exists. The recorder listens; the loop and the strategy know nothing of Rerun:

- every search tick (the loop's ``on_tick``, vehicle time): a probabilistic strategy's source
  posterior and credible circle (``posterior_map()`` / ``credible_region()``, see
  :func:`recording.trial.record_posterior`) at ``posterior_hz``; the vehicle's pose as the mission
  reads it (its local NED frame, yaw only) and the wind the strategy used at ``pose_hz``; the
  flight mode and arming on change;
- every setpoint the mission sends (the vehicle's ``send_setpoint``, after the safety supervisor's
  clamp): ``map/setpoint``, ``world/setpoint``;
- what the mission publishes over MAVLink (the vehicle's ``publish``): strategy states and the declaration.

The search is recorded, from the first search tick to the landing over the declared source; the
take-off and the landing themselves are the autopilot's to record (``windseek sitl --rrd``, or
``windseek review`` of its log). The file opens alone in the viewer (a real vehicle). Beside a
SITL's recording of the same flight, :data:`MISSION_ONLY` names what only the mission knows and
:func:`recording.finalize.rewrite_summary` copies those entities into the SITL's file (``windseek
demo`` does): the same vehicle clock (``time_boot_ms``) and, with windseek's SITL, the same local
frame, so the posterior lies on the map where the truth is.

Conventions: SI, NED (the mission's local frame), vehicle seconds.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr

from recording.recorder import RunRecorder
from recording.scene import ui
from recording.sim_hook import wind_speed_from_deg
from recording.stream import CpuMeter
from recording.summary import RunSummary
from recording.trial import SRC, record_posterior

if TYPE_CHECKING:
    from mission.loop import MissionLoop
    from mission.result import MissionResult

#: Entities only the mission's recording has: what a merge into the SITL's recording copies (rerun content filters).
MISSION_ONLY = ("+ /map/posterior/**", "+ /map/setpoint/**", "+ /world/setpoint/**")
#: Colour of the setpoint marker (RGB): the vehicle's dark grey lightened, so it reads as "where it is told to go".
C_SETPOINT = (120, 120, 120)


class MissionRecorder:
    """Records the mission's side of a run to ``path`` (see the module docstring); rates in Hz of vehicle time.

    Args:
        path: the ``.rrd`` file. strategy, seed, scenario: the recording's name and properties.
        posterior_hz: posterior and credible circle (1 Hz, as an in-process trial's recording).
        posterior_cell_m: the posterior grid's cell [m].
        pose_hz: the vehicle's pose and the strategy's wind.
    """

    def __init__(self, path: Path | str, *, strategy: str | None = None, seed: int | None = None,
                 scenario: str | None = None, posterior_hz: float = 1.0, posterior_cell_m: float = 1.0,
                 pose_hz: float = 5.0) -> None:  # fmt: skip
        self.meter = CpuMeter()  # what recording costs the mission: the recording_cost property
        # Nobody watches the mission's file live: rows go out every 15 s of vehicle time (as the SITL's).
        self.rec = self.meter(lambda: RunRecorder(path, scenario=scenario, strategy=strategy, seed=seed,
                                                  series_flush_s=15.0))  # fmt: skip
        self.rec.log_static("map/setpoint", rr.Points2D.from_fields(radii=ui(3.0), colors=[C_SETPOINT],
                                                                    draw_order=29.0))  # fmt: skip
        self.rec.log_static("world/setpoint", rr.Points3D.from_fields(radii=ui(3.0), colors=[C_SETPOINT]))
        self.posterior_dt = 1.0 / posterior_hz if posterior_hz > 0 else math.inf
        self.pose_dt = 1.0 / pose_hz if pose_hz > 0 else math.inf
        self.cell_m = float(posterior_cell_m)
        self._t_post = self._t_pose = -math.inf
        self._mode, self._armed = "", False
        self._src: dict[str, float] = {}
        self.posteriors = 0  # posteriors logged (a test and the cost figures count them)
        self.posterior_cpu_s = 0.0  # CPU of those logs, the strategy's posterior_map included [s]
        self.loop: MissionLoop | None = None
        self.failed: str | None = None  # why the recording stopped mid-flight (None: it did not)

    def attach(self, loop: MissionLoop) -> None:
        """Listen to ``loop`` (before it flies): its search ticks, the setpoints and status its vehicle sends."""
        self.loop = loop
        v = loop.v
        on_tick, send, publish = loop.on_tick, v.send_setpoint, v.publish

        def tick(t: float) -> None:
            if on_tick is not None:
                on_tick(t)
            self._guard(self._tick, t)

        def sent(pos: np.ndarray | None, vel: np.ndarray | None, yaw: float | None) -> None:
            send(pos, vel, yaw)
            if pos is not None and math.isfinite(v.state.t):
                self._guard(self.rec.setpoint, v.state.t, pos)

        def published(pairs: list[tuple[str, str]]) -> None:
            publish(pairs)
            self._guard(self._on_status, v.state.t, pairs)

        loop.on_tick = tick
        v.send_setpoint = sent  # type: ignore[method-assign]  # a tap: what the mission sends, as sent
        v.publish = published  # type: ignore[method-assign]

    def _guard(self, fn: Any, *args: Any) -> None:
        """Run a recording step, metered; the first failure stops the recording, never the mission (a
        vehicle in flight matters more than its record): said once, the rest of the flight not recorded."""
        if self.failed is not None:
            return
        try:
            self.meter(fn, *args)
        except Exception as e:  # noqa: BLE001 - a disk, rerun or a strategy's posterior_map: any of them
            self.failed = f"{type(e).__name__}: {e}"
            if self.loop is not None:
                self.loop.v.say(f"mission: the recording stopped ({self.failed}); the mission goes on")

    def _tick(self, t: float) -> None:
        loop, rec = self.loop, self.rec
        assert loop is not None
        st = loop.v.state
        if st.armed != self._armed:
            self._armed = st.armed
            rec.armed(t, st.armed)
        if st.mode and st.mode != self._mode:
            self._mode = st.mode
            rec.flight_mode(t, st.mode)
        if t - self._t_pose >= self.pose_dt - 1e-9 and st.pos is not None:
            self._t_pose = t
            h = 0.5 * st.yaw  # yaw only: the mission reads no attitude
            rec.vehicle(t, st.pos, (math.cos(h), 0.0, 0.0, math.sin(h)))
            wi = loop.wind_info
            if wi is not None and math.isfinite(float(wi.wind_ned[0])):
                cov = wi.cov_ned
                sigma = None if cov is None else [math.sqrt(max(float(cov[k][k]), 0.0)) for k in range(3)]
                rec.wind(t, est_ned=wi.wind_ned, sigma_ned=sigma)
                speed, from_deg = wind_speed_from_deg(np.asarray(wi.wind_ned, dtype=float))
                filt = math.degrees(wi.upwind_rad) if math.isfinite(wi.upwind_rad) else None
                rec.wind_speed_dir(t, speed, from_deg, None, filt)
        if t - self._t_post >= self.posterior_dt - 1e-9:
            self._t_post = t
            c0 = time.thread_time()
            if record_posterior(rec, t, loop.strategy, self.cell_m):
                self.posteriors += 1
                self.posterior_cpu_s += time.thread_time() - c0

    def _on_status(self, t: float, pairs: list[tuple[str, str]]) -> None:
        for name, fields in pairs:
            f: dict[str, Any] = json.loads(fields)
            if name == "STATUSTEXT":
                self.rec.mission_statustext(t, str(f.get("text", "")))
            elif name == "NAMED_VALUE_FLOAT":
                key = str(f.get("name", ""))
                if key in SRC:
                    self._src[key] = float(f["value"])
                elif key == "SRC_CONF" and all(k in self._src for k in SRC):
                    region = getattr(self.loop.strategy, "credible_region", None) if self.loop else None
                    got = region() if region is not None else None
                    self.rec.declare(t, [self._src[k] for k in SRC], float(f["value"]),
                                     None if got is None else got[1])  # fmt: skip

    def summary(self, res: MissionResult | None) -> RunSummary:
        """The mission's account of the run (no truth: the mission has none)."""
        rec = self.rec
        s = RunSummary(kind="windseek mission (the mission's side: the strategy's view and its setpoints)",
                       scenario=rec.scenario, strategy=rec.strategy, seed=rec.seed)  # fmt: skip
        if res is not None:
            s.wind_source, s.cause = res.wind_source or res.wind, res.cause or None
            s.outcome = f"mission ended: {res.cause}" if res.cause else "mission ended"
            s.declared_ned, s.confidence = res.declared_ned, res.confidence if res.declared_ned else None
            s.credible_radius_m = res.credible_radius_m if math.isfinite(res.credible_radius_m) else None
            s.time_to_declaration_s = res.time_s if math.isfinite(res.time_s) else None
            s.mission_time_s = res.mission_time_s if math.isfinite(res.mission_time_s) else None
            s.search_path_m = res.path_m
        s.notes = ["no truth in the mission's recording: windseek sitl --rrd (or windseek demo) scores the run"]
        return s

    def close(self, res: MissionResult | None = None) -> None:
        """Write the summary (from the mission's result, if any) and close the file. Idempotent."""
        rec = self.rec
        if rec.closed:
            return
        s = self.summary(res)
        if self.failed is not None:
            s.notes.append(f"the recording stopped mid-flight: {self.failed}")
        self.meter(lambda: rec.summary(s, write=False))
        rec.property("posterior", logged=self.posteriors, cpu_ms_mean=round(
            1e3 * self.posterior_cpu_s / self.posteriors, 3) if self.posteriors else None)  # fmt: skip
        self.meter(rec.close, lambda: self.meter.report(rec))


__all__ = ["C_SETPOINT", "MISSION_ONLY", "MissionRecorder"]
