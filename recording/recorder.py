"""Record a windseek run to a Rerun ``.rrd`` file: the only module family that talks to ``rerun-sdk``.

Every method takes vehicle time ``t`` in seconds (the one timeline, :data:`~recording.style.TIMELINE`)
and SI data in the NED world frame (x north, y east, z down; m, m/s, rad/s, mg/m^3); quaternions are
``[w, x, y, z]`` and rotate body (FRD) vectors into NED; wind is the air-mass velocity (where the air
goes) in NED; wind directions are the meteorological from-direction in degrees.

Entity paths besides the map and 3D ones (:mod:`recording.scene`)::

    wind/{north,east,down}/{truth,estimate,autopilot}   Scalars, m/s
    wind/{north,east,down}/band        Scalars: estimate -+ 2 sigma, two rows per sample (one line zig-zagging
                                       between the edges: a band, one legend entry; RrdLog.band pairs them)
    wind/speed/{raw,filtered,truth,autopilot}            horizontal wind speed, m/s
    wind/direction/{raw,filtered,truth,autopilot}  from-direction, deg, unwrapped: each value within 180 deg of the
                                       series' previous one (the first within 180 deg of the reference), so
                                       the line never jumps by 360 deg; a turning wind runs past 0 or 360
    flight/...                         altitude, velocity, attitude, battery, GPS (:mod:`recording.flight_plots`)
    chem/log10, chem/threshold_log10   log10 mg/m^3 (the plot); each row also carries the reading (the threshold)
                                       in mg/m^3 as ``Chem:mg_m3``: the series chem/value, chem/threshold
    rotors                             rad/s, 4 values a row: the series rotors/1 .. rotors/4 (recording.series)
    extra/<name>                       any other scalar (:meth:`RunRecorder.scalar`)
    phases/{mission,strategy,mode}     StateChange lanes: mission phase, strategy state, flight mode
    markers/{phase,verify,declared}    vertical lines at the phases (written at close)
    log/<channel>                      TextLog: events (autopilot), mission, wire, review
    summary                            TextDocument (Markdown): the run summary
    missing/<panel>                    TextDocument: why a panel has no data (the layout shows it instead)

Cost and rates: a per-tick call costs a few to tens of microseconds (rows, the path's segments
and the hits included, are buffered and sent as columns, :mod:`recording.stream`); plume slices,
text and state changes are logged at once. Recommended rates: pose and wind arrows 20-50 Hz,
series 20-50 Hz (chemical at its sensor rate), plume slice 0.2-1 Hz, text on change only.

A recorder is not thread-safe. Each instance owns a separate ``rr.RecordingStream`` with a fresh
recording id and never touches rerun's global recording, so several can coexist in one process.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

import numpy as np
import rerun as rr

from recording.events import EventsMixin
from recording.flight_plots import FLIGHT_SERIES, FlightPlotsMixin
from recording.layout import OPTIONAL_PLOTS, PLOTS, Layout, make_blueprint
from recording.phases import MARKER_KINDS
from recording.ranges import fit_ranges
from recording.series import CARRIED, row_styles
from recording.style import (
    AXES,
    C_AUTOPILOT,
    C_BAND,
    C_EST,
    C_MARK_DECLARED,
    C_MARK_PHASE,
    C_MARK_VERIFY,
    C_RAW,
    C_THRESH,
    C_TRUTH,
    PHASE_COLORS,
    PHASES,
    VecLike,
)
from recording.summary import RunSummary
from recording.urban_scene import UrbanSceneMixin

#: Time between the two edges of one crossing of the +-2 sigma band [s] (far below a pixel).
BAND_DT = 1.0e-4
#: Marker lines span this far up and down [plot units]: every plot has a fixed value range. Above
#: every plot's values (rotor speeds stay below 1e4 rad/s), not far beyond: the viewer drops a line
#: that ends ~1e7 px off its plot (at 1e6 the markers vanished from a 1 m/s wind plot 100 px tall).
MARKER_SPAN = 1.0e4
#: Why a plot is empty (the layout shows the line instead), by plot key.
NO_DATA = {"chem": "no chemical readings", "rotors": "no rotor speeds", "speed": "no wind estimate or truth",
           "altitude": "no positions", "gps": "no GPS fixes", "remaining": "no remaining charge"}  # fmt: skip
_MARKERS = {"phase": ("take-off · search · landing", C_MARK_PHASE), "verify": ("verification", C_MARK_VERIFY),
            "declared": ("declared", C_MARK_DECLARED)}  # fmt: skip


class RunRecorder(EventsMixin, UrbanSceneMixin, FlightPlotsMixin):
    """Writes one run to a ``.rrd`` file (see the module docstring for paths, units and rates).

    Args:
        path: output ``.rrd`` file. application_id: Rerun application id.
        scenario, strategy, seed: recording name and properties.
        blueprint: send the layout (:mod:`recording.layout`) at close, fitted to the run.
        live_layout: also send a starting layout now, for a viewer that watches the run as it is
            recorded (about 5 ms of CPU; a recording that is only read after the run skips it). Without
            it the static data (styles, map furniture) is also kept until close and sent once
            (``RecorderBase(defer_static=True)``: fewer chunks, a smaller file).
        series_flush_s: vehicle seconds between two sends of the buffered rows.
        trail_min_step_m: the path gets a segment whenever the vehicle moved this far [m].
        c_range_mg_m3: (low, high) of the concentration colour scale [mg/m^3]; the chemical plot's
            floor (a reading of 0 is drawn at ``low``).
        arrow_scale_s: wind arrow length per m/s of wind [m / (m/s)].
        recording_id: reuse a recording id (default: a fresh one).
        estimate_label, autopilot_label: what the legends call windseek's estimate (``estimate N``) and
            the autopilot's own (``autopilot N``; with PX4 flying ``PX4 EKF2 N``, with ArduCopter
            ``ArduCopter EKF3 N``).
        footer: end the file with rerun's chunk manifest (``RecorderBase``: a batch trial leaves it out).
        png_images: send a posterior and the urban layers' static images as PNGs (the same pixels, less
            than half the bytes, :mod:`recording.png`), else as raw RGBA (``rr.Image``, as before 2026-12-06).
        shared_rows: series logged together share rows (:mod:`recording.series`: the rotors, the chemical
            reading with its log10); False: an entity each, as before 2026-12-06 (``RecorderBase``).

    Use as a context manager, or call :meth:`close` at the end.
    """

    def __init__(self, path: Path | str, application_id: str = "windseek", *, scenario: str | None = None,
                 strategy: str | None = None, seed: int | None = None, blueprint: bool = True,
                 live_layout: bool = True,
                 series_flush_s: float = 4.0, trail_min_step_m: float = 0.5,
                 c_range_mg_m3: tuple[float, float] = (1e-2, 1e2),
                 arrow_scale_s: float = 2.0, recording_id: str | None = None, estimate_label: str = "estimate",
                 autopilot_label: str = "autopilot", png_images: bool = True,
                 footer: bool = True, shared_rows: bool = True) -> None:  # fmt: skip
        super().__init__(path, application_id, series_flush_s=series_flush_s, recording_id=recording_id,
                         defer_static=not live_layout, footer=footer, shared_rows=shared_rows)  # fmt: skip
        self.trail_min_step_m = float(trail_min_step_m)
        self.c_range_mg_m3 = (float(c_range_mg_m3[0]), float(c_range_mg_m3[1]))
        self.arrow_scale_s = float(arrow_scale_s)
        self.png_images = bool(png_images)
        self.blueprint = blueprint
        self.scenario, self.strategy, self.seed = scenario, strategy, seed
        self.estimate_label, self.autopilot_label = estimate_label, autopilot_label
        self.missing: dict[str, str] = {}
        self.chem_threshold: float | None = None
        self._summary: RunSummary | None = None
        self._dir_ref: float | None = None
        self._dir_last: dict[str, float] = {}  # the last unwrapped value of each direction series
        self.first_tab = "wind"  # the tab of plots the layout opens on (recording.layout.TABS)
        self._band_up = True
        self._init_events()
        self.rec.send_recording_name(" / ".join(str(s) for s in (scenario, strategy) if s) or "windseek run")
        self.property("windseek", scenario=scenario, strategy=strategy, seed=seed)
        self._init_scene()
        self._send_static()
        if blueprint and live_layout:
            self.rec.send_blueprint(make_blueprint(), make_active=True, make_default=True)

    def _send_static(self) -> None:
        """Series names, colours and widths: static, so the rows carry only data."""
        for a in AXES:  # the axis in every name: a legend says which component a plot shows
            k = a[0].upper()
            self._style(f"wind/{a}/truth", f"truth {k}", C_TRUTH, 2.0)
            self._style(f"wind/{a}/estimate", f"{self.estimate_label} {k}", C_EST, 2.0)
            self._style(f"wind/{a}/autopilot", f"{self.autopilot_label} {k}", C_AUTOPILOT, 1.5)
            # The band is one line zig-zagging between its edges (see wind()): never averaged, or the
            # viewer's aggregation of several rows per pixel would fold it onto the estimate.
            self.log_static(f"wind/{a}/band", rr.SeriesLines(names=f"±2σ band {k}", colors=[C_BAND], widths=1.0,
                                                             aggregation_policy="Off"))  # fmt: skip
        for q in ("speed", "direction"):
            self._style(f"wind/{q}/filtered", "filtered", C_EST, 2.0)
            self._style(f"wind/{q}/truth", "truth", C_TRUTH, 2.0)
            # Raw estimates scatter (and directions near 0 deg would zig-zag): points, not a line.
            self.log_static(f"wind/{q}/raw", rr.SeriesPoints(names="raw", colors=[C_RAW], marker_sizes=1.0))
        for q in ("speed", "direction"):
            self._style(f"wind/{q}/autopilot", self.autopilot_label, C_AUTOPILOT, 1.5)
        self._style("chem/log10", "reading", C_TRUTH, 1.5)
        self._style("chem/threshold_log10", "detection threshold", C_THRESH, 1.5)
        for entity, style in row_styles(self.shared_rows):  # the rotors; chem/value rides in chem/log10's rows
            self.log_static(entity, style)
        for kind, (name, c) in _MARKERS.items():
            self.log_static(f"markers/{kind}", rr.SeriesLines(names=name, colors=[c], widths=1.5,
                                                              aggregation_policy="Off"))  # fmt: skip
        self.log_static("phases/mission", rr.StateConfiguration(values=list(PHASES), colors=list(PHASE_COLORS)))
        for entity, (name, c) in FLIGHT_SERIES.items():
            self._style(entity, name, c, 1.5)

    def _style(self, entity: str, name: str, color: tuple[int, int, int], width: float) -> None:
        self.log_static(entity, rr.SeriesLines(names=name, colors=[color], widths=width))

    # ------------------------------------------------------------------ time series
    def wind(self, t: float, truth_ned: VecLike | None = None, est_ned: VecLike | None = None,
             sigma_ned: VecLike | None = None) -> None:  # fmt: skip
        """Wind per NED axis [m/s]: truth, estimate, and the band estimate -+ 2 sigma (``sigma_ned`` is
        the 1-sigma standard deviation per axis, needs ``est_ned``).

        Rerun 0.41 cannot fill between two lines, so the band is one translucent line that crosses
        it at every sample: two rows, one edge at ``t`` and the other :data:`BAND_DT` later, the
        order alternating (up at one sample, down at the next, along an edge in between). At the
        estimator's 10-25 Hz a flight's plot has several crossings per pixel, which read as a
        filled band; zoomed in, as a hatched one."""
        t = float(t)
        band = sigma_ned is not None and est_ned is not None
        t_last = max(self.t_last, t)  # the band's second row is not a later time of the run
        for k, a in enumerate(AXES):
            if truth_ned is not None:
                self._push(f"wind/{a}/truth", t, truth_ned[k])
            if est_ned is not None:
                e = float(est_ned[k])
                self._push(f"wind/{a}/estimate", t, e)
                if band and sigma_ned is not None:
                    s = 2.0 * float(sigma_ned[k])
                    if math.isfinite(e) and math.isfinite(s):
                        first, second = (e - s, e + s) if self._band_up else (e + s, e - s)
                        self._push(f"wind/{a}/band", t, first)
                        self._push(f"wind/{a}/band", t + BAND_DT, second)
        if band:
            self._band_up = not self._band_up
            self.t_last = t_last
        self._maybe_flush(t)

    def set_wind_reference(self, from_deg: float) -> None:
        """The from-direction [deg] the direction plot is centred on (default: the first value logged)."""
        self._dir_ref = float(from_deg)

    def _unwrap(self, name: str, deg: float | None) -> float | None:
        """A from-direction [deg] of series ``name`` within 180 deg of its previous value (the first
        within 180 deg of the reference): consecutive values never jump by 360 deg."""
        if deg is None or not math.isfinite(float(deg)):
            return None
        if self._dir_ref is None:
            self._dir_ref = float(deg) % 360.0
        ref = self._dir_last.get(name, self._dir_ref)
        out = ref + ((float(deg) - ref + 180.0) % 360.0) - 180.0
        self._dir_last[name] = out
        return out

    def wind_speed_dir(self, t: float, speed_raw: float | None, dir_raw_deg: float | None,
                       speed_filt: float | None = None, dir_filt_deg: float | None = None,
                       truth_speed: float | None = None, truth_dir_deg: float | None = None) -> None:  # fmt: skip
        """Horizontal wind speed [m/s] and from-direction [deg, 0 = from north, 90 = from east]: raw
        (per-sample) estimate, filtered estimate and truth; directions unwrapped about a reference."""
        t = float(t)
        for name, v in (("raw", speed_raw), ("filtered", speed_filt), ("truth", truth_speed)):
            self._push(f"wind/speed/{name}", t, v)
        for name, d in (("truth", truth_dir_deg), ("filtered", dir_filt_deg), ("raw", dir_raw_deg)):
            self._push(f"wind/direction/{name}", t, self._unwrap(name, d))
        self._maybe_flush(t)

    def autopilot_wind(self, t: float, wind_ned: VecLike) -> None:
        """An autopilot's own wind estimate [m/s, NED air-mass velocity]; NaN components are gaps. Also
        its horizontal speed and from-direction [deg] (none in a calm below 0.05 m/s: no direction)."""
        t = float(t)
        for k, a in enumerate(AXES):
            self._push(f"wind/{a}/autopilot", t, float(wind_ned[k]))
        n, e = float(wind_ned[0]), float(wind_ned[1])
        speed = math.hypot(n, e)
        self._push("wind/speed/autopilot", t, speed)
        if speed >= 0.05:
            self._push("wind/direction/autopilot", t, self._unwrap("autopilot", math.degrees(math.atan2(-e, -n)) % 360))
        self._maybe_flush(t)

    def set_chem_threshold(self, threshold_mg_m3: float) -> None:
        """The detection threshold [mg/m^3]: drawn on the chemical plot; readings at or above it are hits."""
        self.chem_threshold = float(threshold_mg_m3)

    def chem(self, t: float, value_mg_m3: float, threshold_mg_m3: float | None = None) -> None:
        """A chemical reading [mg/m^3] (0 = below detection); a hit is also drawn on the map."""
        t = float(t)
        if threshold_mg_m3 is not None and math.isfinite(threshold_mg_m3):
            self.chem_threshold = float(threshold_mg_m3)
        v = float(value_mg_m3)
        if not math.isfinite(v):
            return
        self._push_scalars("chem/log10", t, [math.log10(max(v, self.c_range_mg_m3[0]))], {CARRIED["chem/value"][1]: v})
        thr = self.chem_threshold
        if v > 0.0 and (thr is None or v >= thr):
            self._hit(v)
        self._maybe_flush(t)

    def rotors(self, t: float, rad_s_4: VecLike) -> None:
        """Rotor speeds [rad/s], rotors 1-4 in the vehicle file's order."""
        t = float(t)
        self._push_scalars("rotors", t, [rad_s_4[i] for i in range(4)])
        self._maybe_flush(t)

    def scalar(self, t: float, name: str, value: float) -> None:
        """Any other scalar series, at ``extra/<name>`` (units in the name, e.g. "nis", "tilt_deg")."""
        t = float(t)
        self._push(f"extra/{name}", t, value)
        self._maybe_flush(t)

    # ------------------------------------------------------------------ summary and end
    def summary(self, s: RunSummary, write: bool = True) -> None:
        """The run summary (the summary panel and the ``result`` property); completed at close with
        the phase times the recorder saw. Calling it again replaces it. ``write=False`` keeps it for
        :meth:`close` to write (once, when closing right after)."""
        self._summary = s
        if write:
            self._write_summary()

    def _write_summary(self) -> None:
        s = self._summary
        assert s is not None
        p = self.phases
        for name, v in (("t_arm_s", p.t_arm), ("t_search_s", p.t_search), ("t_declared_s", p.t_declared),
                        ("t_disarm_s", p.t_disarm)):  # fmt: skip
            if getattr(s, name) is None and math.isfinite(v):
                setattr(s, name, round(v, 2))
        if not s.verifications and p.verifications:
            s.verifications = [{"t_start_s": round(a, 2), "duration_s": None if math.isnan(b) else round(b - a, 2),
                                "outcome": ""} for a, b in p.verifications]  # fmt: skip
        if not s.true_sources_ned and self.true_sources_ned:
            s.true_sources_ned = self.true_sources_ned
        if s.declared_ned is None and self.declaration is not None:
            s.declared_ned, s.confidence = self.declaration[1], self.declaration[2]
        for m in self.missing.values():
            if m not in s.missing:
                s.missing.append(m)
        s.score()
        self.log_static("summary", rr.TextDocument(s.markdown(), media_type="text/markdown"))
        self.property("result", **s.properties())

    def note_missing(self, panel: str, why: str) -> None:
        """Say why a panel (``map``, ``chem``, ``rotors``, ``north``, ...) has no data (shown instead of it)."""
        self.missing[panel] = why

    def _send_markers(self) -> bool:
        sent = False
        for kind in MARKER_KINDS:
            ts = [m.t for m in self.phases.markers if m.kind == kind]
            if not ts:
                continue
            t = np.repeat(ts, 3)
            v = np.tile([-MARKER_SPAN, MARKER_SPAN, math.nan], len(ts))  # NaN: a gap between two markers
            self.send_columns(f"markers/{kind}", t, rr.Scalars.columns(scalars=v))
            sent = True
        return sent

    def _layout(self) -> Layout:
        lay = Layout(bounds_ne=self.scene_bounds(), altitude_m=self.flight_altitude_m, top_m=self.top_m)
        span = self.phases.flight_span()
        if math.isfinite(self.t_first):
            t0, t1 = self.t_first, self.t_last
            if span is not None:
                t0 = max(t0, span[0] - 3.0)
                t1 = min(t1, span[1] + 3.0) if math.isfinite(span[1]) else t1
            lay.t_range = (round(t0, 2), round(max(t1, t0 + 1.0), 2))
            lay.y_ranges = fit_ranges(self, lay.t_range)
        lay.missing = dict(self.missing)
        lay.first_tab = self.first_tab
        for key, entities in (("chem", ("chem/log10",)), ("rotors", ("rotors/1",)),
                              ("speed", ("wind/speed/truth", "wind/speed/raw", "wind/speed/autopilot")),
                              *((k, tuple(e for e in FLIGHT_SERIES if e.startswith(f"flight/{g}/"))) for k, g in
                                (("altitude", "altitude"), ("velocity", "velocity"), ("attitude", "attitude"),
                                 ("gps", "gps"))),
                              *((k, (f"flight/battery/{k}",)) for k in ("voltage", "current", "remaining")),
                              ):  # fmt: skip
            if key not in lay.missing and not any(self.has_series(e) for e in entities):
                lay.missing[key] = NO_DATA.get(key, f"no {key} in this recording")
        for a in AXES:
            if "speed" in lay.missing and a not in lay.missing:
                lay.missing[a] = lay.missing["speed"]
        if "direction" not in lay.missing and "speed" in lay.missing:
            lay.missing["direction"] = lay.missing["speed"]
        if "map" not in lay.missing and not self.has_series("world/vehicle"):
            lay.missing["map"] = "no positions: no path to draw"
        return lay

    def close(self, cost: Callable[[], dict[str, float]] | None = None) -> None:
        """Send everything buffered, the markers, the summary and the final layout; close the file.
        ``cost`` gives the ``recording_cost`` property, asked for last (all but the final flush
        counted). Idempotent."""
        if self.closed:
            return
        self.flush_series()
        thr = self.chem_threshold
        if thr is not None and thr > 0 and self.has_series("chem/value"):
            for t in (self.t_first, self.t_last):
                self._push_scalars("chem/threshold_log10", t, [math.log10(max(thr, self.c_range_mg_m3[0]))],
                                   {CARRIED["chem/threshold"][1]: thr})  # fmt: skip
            self.flush_series()
        lay = self._layout()
        lay.markers = self._send_markers()
        self.send_furniture(lay.bounds_ne or self.scene_bounds())
        for key, why in lay.missing.items():
            if key in OPTIONAL_PLOTS:
                continue  # left out of the layout, not replaced by a line
            title = PLOTS[key][0] if key in PLOTS else key
            self.log_static(f"missing/{key}", rr.TextDocument(f"**{title}**: {why}.", media_type="text/markdown"))
        if self._summary is None:
            self._summary = RunSummary(kind="recording", scenario=self.scenario, strategy=self.strategy,
                                       seed=self.seed)  # fmt: skip
        self._write_summary()
        self.property("layout", json=lay.to_json())
        self._send_deferred_static()
        if self.blueprint:
            self.rec.send_blueprint(make_blueprint(lay), make_active=True, make_default=True)
        if cost is not None:
            # Blocking: rerun's threads encode and write everything sent so far before their CPU is read.
            self.rec.flush()
            self.property("recording_cost", **cost())
        self._close_stream()

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:  # fmt: skip
        self.close()


__all__ = ["BAND_DT", "MARKER_SPAN", "RunRecorder"]
