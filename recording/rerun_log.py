"""Record a windseek run to a Rerun ``.rrd`` file: the only module that talks to ``rerun-sdk``.

Every method takes simulation time ``t`` in seconds and SI data in the NED world frame
(x north, y east, z down; m, m/s, rad/s, mg/m^3); quaternions are ``[w, x, y, z]`` and rotate
body (FRD) vectors into NED; wind is the air-mass velocity (where the air goes) in NED, wind
directions are the meteorological from-direction in degrees. All data lands on one timeline,
``sim_time`` (a duration, so the viewer shows seconds of simulated time).

Entity paths (the viewer groups by these; :mod:`recording.read` finds them again)::

    world                              ViewCoordinates FRD = NED (x north, y east, z down), static
    world/vehicle                      Transform3D: position (NED) + attitude (body FRD -> NED)
    world/vehicle/body                 Boxes3D, static (drawn in the body frame)
    world/vehicle/axes                 Arrows3D F (red), R (green), D (blue), static
    world/trail                        LineStrips3D of the path flown so far (decimated)
    world/sources/true                 Points3D, static
    world/sources/declared             Points3D, labelled with the declared confidence
    world/plume/slice                  Points3D coloured by log10 concentration at flight altitude
    world/plume/puffs                  Points3D, radius = puff sigma
    world/wind/truth                   Arrows3D at the vehicle (air-mass velocity * arrow_scale_s)
    world/wind/estimate                Arrows3D at the vehicle
    world/geofence                     Boxes3D, static
    wind/{north,east,down}/truth       Scalars, m/s
    wind/{north,east,down}/estimate    Scalars, m/s
    wind/{north,east,down}/lower       Scalars, estimate - 2 sigma, m/s
    wind/{north,east,down}/upper       Scalars, estimate + 2 sigma, m/s
    wind/speed/{raw,filtered,truth}    Scalars, horizontal wind speed, m/s
    wind/direction/{raw,filtered,truth}  Scalars, from-direction, deg in [0, 360)
    chem/value, chem/threshold         Scalars, mg/m^3
    rotors/{1,2,3,4}                   Scalars, rad/s
    log/<channel>                      TextLog (mode changes, strategy states; channel "events" by default)
    extra/<name>                       Scalars from :meth:`RunRecorder.scalar` (anything else a runner wants)

Cost and rates. A per-tick call costs a few to tens of microseconds: the high-rate entities
(scalar series, vehicle pose, wind arrows) are buffered in Python lists and sent as columns
(``send_columns``) every ``series_flush_s`` of simulated time (so a live viewer lags by that
much), the static geometry and styles (vehicle body, axes, colours) are sent once, and the
trail is re-sent at most every ``trail_every_s``. The low-rate entities (plume slice, puffs,
text, sources) are logged at once (30-300 us each). The caller decides the rates; recommended:

    vehicle pose, wind arrows        20-50 Hz
    time series (wind, chem, rotors) 20-50 Hz (chem at its sensor rate)
    plume slice                      0.5-1 Hz (a 60 x 30 grid is 1800 points)
    puffs                            2-5 Hz
    text                             on change only

A recorder is not thread-safe (one ``RecordingStream`` with its own current time); use it
from one thread or one asyncio loop. Each instance owns a separate ``rr.RecordingStream``
with a fresh recording id and never touches rerun's global recording, so several recorders
can coexist in one process.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

#: Timeline every entity is logged on (simulation seconds, as a duration).
TIMELINE = "sim_time"
AXES = ("north", "east", "down")
TEXT_LEVELS = ("TRACE", "DEBUG", "INFO", "WARN", "ERROR", "CRITICAL")

# Colours (RGB): truth blue, estimate orange, band light orange, raw grey, threshold red.
C_TRUTH = (31, 119, 180)
C_EST = (255, 127, 14)
C_BAND = (255, 195, 140)
C_RAW = (150, 150, 150)
C_THRESH = (214, 39, 40)
C_ROTORS = ((228, 26, 28), (55, 126, 184), (77, 175, 74), (152, 78, 163))

# Anchors of the viridis colour map (0 = low, 1 = high): dark purple -> blue -> green -> yellow.
_CMAP_X = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
_CMAP_RGB = np.array(
    [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=float
)


def log_colormap(c: np.ndarray, c_min: float, c_max: float) -> np.ndarray:
    """Map concentrations [mg/m^3] to RGB (N, 3) uint8 on a log10 scale between c_min and c_max.

    Values at or below ``c_min`` get the lowest colour, at or above ``c_max`` the highest;
    a log scale because a plume spans decades between its core and its edge.
    """
    c = np.asarray(c, dtype=float).ravel()
    lo, hi = math.log10(c_min), math.log10(c_max)
    s = (np.log10(np.maximum(c, c_min)) - lo) / (hi - lo)
    s = np.clip(s, 0.0, 1.0)
    rgb = np.column_stack([np.interp(s, _CMAP_X, _CMAP_RGB[:, k]) for k in range(3)])
    return np.round(rgb).astype(np.uint8)


class _ColumnBuffer:
    """Rows of one entity waiting to be sent as columns: times [s] and per-field values."""

    __slots__ = ("archetype", "fields", "t")

    def __init__(self, archetype: type) -> None:
        self.archetype = archetype
        self.t: list[float] = []
        self.fields: dict[str, list] = {}

    def clear(self) -> None:
        self.t.clear()
        for v in self.fields.values():
            v.clear()


def make_blueprint() -> rrb.Blueprint:
    """Default viewer layout: 3D world on the left, wind / chemical / rotor series stacked on the
    right, the text log along the bottom, the time panel on ``sim_time``."""
    wind_axes = rrb.Horizontal(
        *(rrb.TimeSeriesView(origin=f"wind/{a}", name=f"wind {a} (m/s)") for a in AXES)
    )
    speed_dir = rrb.Horizontal(
        rrb.TimeSeriesView(origin="wind/speed", name="wind speed (m/s)"),
        rrb.TimeSeriesView(origin="wind/direction", name="wind from (deg)"),
    )
    series = rrb.Vertical(
        wind_axes,
        speed_dir,
        rrb.TimeSeriesView(origin="chem", name="chemical (mg/m^3)"),
        rrb.TimeSeriesView(origin="rotors", name="rotor speeds (rad/s)"),
    )
    top = rrb.Horizontal(rrb.Spatial3DView(origin="world", name="world (NED)"), series, column_shares=[3, 2])
    return rrb.Blueprint(
        rrb.Vertical(top, rrb.TextLogView(origin="log", name="events"), row_shares=[5, 1]),
        rrb.TimePanel(timeline=TIMELINE),
        collapse_panels=False,
    )


class RunRecorder:
    """Writes one run to a ``.rrd`` file (see the module docstring for paths, units and rates).

    Args:
        path: output ``.rrd`` file (parent folders are created).
        application_id: Rerun application id (the viewer groups recordings by it).
        scenario, strategy, seed: stored as recording properties and in the recording name.
        blueprint: send :func:`make_blueprint` as the default layout.
        series_flush_s: simulated seconds between two sends of the buffered scalar series.
        trail_min_step_m: a trail point is kept once the vehicle moved this far [m].
        trail_every_s: simulated seconds between two re-sends of the trail.
        trail_max_points: the trail is thinned by 2 whenever it grows past this.
        c_range_mg_m3: (low, high) of the log colour scale of the plume slice [mg/m^3];
            cells below ``low`` are not drawn.
        arrow_scale_s: wind arrow length per m/s of wind [m / (m/s)].

    Use as a context manager, or call :meth:`close` at the end (it sends what is buffered).
    """

    def __init__(
        self,
        path: Path | str,
        application_id: str = "windseek",
        *,
        scenario: str | None = None,
        strategy: str | None = None,
        seed: int | None = None,
        blueprint: bool = True,
        series_flush_s: float = 0.5,
        trail_min_step_m: float = 0.25,
        trail_every_s: float = 1.0,
        trail_max_points: int = 4000,
        c_range_mg_m3: tuple[float, float] = (1e-2, 1e2),
        arrow_scale_s: float = 1.0,
    ) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.series_flush_s = float(series_flush_s)
        self.trail_min_step_m = float(trail_min_step_m)
        self.trail_every_s = float(trail_every_s)
        self.trail_max_points = int(trail_max_points)
        self.c_range_mg_m3 = (float(c_range_mg_m3[0]), float(c_range_mg_m3[1]))
        self.arrow_scale_s = float(arrow_scale_s)
        # A fresh recording id per instance: the default id is shared process-wide, which
        # would merge two recorders (or two test runs) into one recording.
        self.rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        # Wall-clock "log_time" means nothing for a lockstep simulation and costs per call.
        self.rec.set_log_time_enabled(False)
        self.rec.save(self.path, default_blueprint=make_blueprint() if blueprint else None)
        self._closed = False
        self._t_last = 0.0
        self._series: dict[str, _ColumnBuffer] = {}
        self._t_flush = -math.inf
        self._trail: list[np.ndarray] = []
        self._t_trail = -math.inf
        self._trail_dirty = False
        self._send_meta(scenario, strategy, seed)
        self._send_static()

    # ------------------------------------------------------------------ set-up
    def _send_meta(self, scenario: str | None, strategy: str | None, seed: int | None) -> None:
        name = " / ".join(str(s) for s in (scenario, strategy) if s) or "windseek run"
        self.rec.send_recording_name(name)
        props = {k: v for k, v in (("scenario", scenario), ("strategy", strategy), ("seed", seed)) if v is not None}
        if props:
            self.rec.send_property("windseek", rr.AnyValues(**props))

    def _send_static(self) -> None:
        """Coordinate convention, vehicle geometry and series styles: sent once, static."""
        log = self.rec.log
        # NED is "forward-right-down" with forward = north: the viewer then knows -z is up.
        log("world", rr.ViewCoordinates.FRD, static=True)
        log(
            "world/vehicle/body",
            rr.Boxes3D(half_sizes=[[0.35, 0.35, 0.06]], colors=[(90, 90, 90)], fill_mode="MajorWireframe"),
            static=True,
        )
        log(
            "world/vehicle/axes",
            rr.Arrows3D(
                origins=np.zeros((3, 3)),
                vectors=np.eye(3) * 0.6,
                colors=[(230, 40, 40), (40, 180, 40), (40, 80, 230)],
                labels=["F", "R", "D"],
            ),
            static=True,
        )
        # Colours and widths of the per-tick entities are static, so the rows carry only data.
        log("world/wind/truth", rr.Arrows3D.from_fields(colors=[C_TRUTH], radii=0.06, labels=["wind"]), static=True)
        log(
            "world/wind/estimate", rr.Arrows3D.from_fields(colors=[C_EST], radii=0.06, labels=["estimate"]), static=True
        )
        for a in AXES:
            self._style(f"wind/{a}/truth", "truth", C_TRUTH, 2.0)
            self._style(f"wind/{a}/estimate", "estimate", C_EST, 2.0)
            self._style(f"wind/{a}/lower", "estimate - 2 sigma", C_BAND, 1.0)
            self._style(f"wind/{a}/upper", "estimate + 2 sigma", C_BAND, 1.0)
        for q in ("speed", "direction"):
            self._style(f"wind/{q}/filtered", "filtered", C_EST, 2.0)
            self._style(f"wind/{q}/truth", "truth", C_TRUTH, 2.0)
        self._style("wind/speed/raw", "raw", C_RAW, 1.0)
        # Raw directions jump across 0/360 deg: points, so no vertical lines at every wrap.
        log("wind/direction/raw", rr.SeriesPoints(names="raw", colors=[C_RAW], marker_sizes=1.5), static=True)
        self._style("chem/value", "reading", C_TRUTH, 1.5)
        self._style("chem/threshold", "threshold", C_THRESH, 1.0)
        for i, c in enumerate(C_ROTORS, start=1):
            self._style(f"rotors/{i}", f"rotor {i}", c, 1.5)

    def _style(self, entity: str, name: str, color: tuple[int, int, int], width: float) -> None:
        self.rec.log(entity, rr.SeriesLines(names=name, colors=[color], widths=width), static=True)

    # ------------------------------------------------------------------ internals
    def _time(self, t: float) -> None:
        t = float(t)
        self._t_last = max(self._t_last, t)
        self.rec.set_time(TIMELINE, duration=t)

    def _push(self, entity: str, t: float, value: float | None) -> None:
        """Buffer one scalar (skipped when None or not finite: a gap, not a zero)."""
        if value is None:
            return
        v = float(value)
        if not math.isfinite(v):
            return
        self._push_row(entity, rr.Scalars, t, scalars=v)

    def _push_row(self, entity: str, archetype: type, t: float, **fields: object) -> None:
        """Buffer one temporal row of ``archetype`` (one instance per row) for :meth:`flush_series`."""
        if t > self._t_last:
            self._t_last = t
        buf = self._series.get(entity)
        if buf is None:
            buf = self._series[entity] = _ColumnBuffer(archetype)
        buf.t.append(float(t))
        for name, value in fields.items():
            buf.fields.setdefault(name, []).append(value)

    def _maybe_flush(self, t: float) -> None:
        if t - self._t_flush >= self.series_flush_s:
            self.flush_series()
            self._t_flush = t

    def flush_series(self) -> None:
        """Send the buffered rows now (done automatically every ``series_flush_s`` of sim time).

        One ``send_columns`` per entity for all rows since the last flush: this is what keeps
        a per-tick call at a few microseconds (a ``log`` call costs 30-100 us).
        """
        for entity, buf in self._series.items():
            if not buf.t:
                continue
            cols = {name: np.asarray(v, dtype=float) for name, v in buf.fields.items()}
            self.rec.send_columns(
                entity,
                indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(buf.t))],
                columns=buf.archetype.columns(**cols),
            )
            buf.clear()

    # ------------------------------------------------------------------ 3D world
    def vehicle(self, t: float, pos_ned: Sequence[float], quat_wxyz: Sequence[float]) -> None:
        """Vehicle pose: position [m, NED] and attitude quaternion [w, x, y, z] (body FRD -> NED).

        Also extends the trail (points at least ``trail_min_step_m`` apart, re-sent every
        ``trail_every_s``).
        """
        t = float(t)
        # Copies: callers pass views of live state (sim.x[0:3]) and rows are sent later.
        p = np.array(pos_ned, dtype=float)
        q = np.array(quat_wxyz, dtype=float)
        self._push_row("world/vehicle", rr.Transform3D, t, translation=p, quaternion=(q[1], q[2], q[3], q[0]))
        if not self._trail or np.linalg.norm(p - self._trail[-1]) >= self.trail_min_step_m:
            self._trail.append(p.copy())
            self._trail_dirty = True
            if len(self._trail) > self.trail_max_points:
                # Thin by 2, keeping the start and the newest point, so the strip stays cheap to re-send.
                thinned = self._trail[::2]
                if len(self._trail) % 2 == 0:
                    thinned.append(self._trail[-1])
                self._trail = thinned
        if self._trail_dirty and t - self._t_trail >= self.trail_every_s:
            self._time(t)
            self._send_trail()
            self._t_trail = t
        self._maybe_flush(t)

    def _send_trail(self) -> None:
        if len(self._trail) >= 2:
            self.rec.log("world/trail", rr.LineStrips3D([np.array(self._trail)], colors=[(255, 140, 0)], radii=0.05))
        self._trail_dirty = False

    def sources(
        self,
        true_ned_list: Sequence[Sequence[float]],
        declared_ned: Sequence[float] | None = None,
        confidence: float | None = None,
        t: float | None = None,
    ) -> None:
        """Chemical sources: true positions [m, NED] (static) and a declared estimate.

        The declared source is logged at ``t`` [s] (default: the latest time logged so far,
        so it appears when the strategy declares it); ``confidence`` in [0, 1] labels it.
        """
        true = np.asarray(true_ned_list, dtype=float).reshape(-1, 3)
        if len(true):
            self.rec.log(
                "world/sources/true",
                rr.Points3D(
                    true,
                    radii=0.6,
                    colors=[C_THRESH],
                    labels=[f"source {i + 1}" for i in range(len(true))],
                ),
                static=True,
            )
        if declared_ned is not None:
            self._time(self._t_last if t is None else t)
            label = "declared" if confidence is None else f"declared ({100.0 * float(confidence):.0f}%)"
            self.rec.log(
                "world/sources/declared",
                rr.Points3D(np.asarray(declared_ned, dtype=float).reshape(1, 3), radii=0.6, colors=[(44, 160, 44)],
                            labels=[label]),
            )

    def plume_slice(self, t: float, xs: np.ndarray, ys: np.ndarray, C: np.ndarray, z: float) -> None:
        """Horizontal concentration slice at NED depth ``z`` [m].

        ``C[i, j]`` [mg/m^3] is the concentration at (``xs[i]``, ``ys[j]``, z) (the layout of
        ``sitl.world.plume.*.slice_grid``). Drawn as coloured points on a log scale between
        ``c_range_mg_m3``; cells below its low end are left out, so the slice shows the plume
        and not a carpet of background points.
        """
        xs = np.asarray(xs, dtype=float)
        ys = np.asarray(ys, dtype=float)
        conc = np.asarray(C, dtype=float).reshape(len(xs), len(ys))
        self._time(t)
        i, j = np.nonzero(conc >= self.c_range_mg_m3[0])
        pts = np.column_stack([xs[i], ys[j], np.full(len(i), float(z))])
        dx = float(np.min(np.diff(xs))) if len(xs) > 1 else 1.0
        dy = float(np.min(np.diff(ys))) if len(ys) > 1 else 1.0
        self.rec.log(
            "world/plume/slice",
            rr.Points3D(pts, radii=0.5 * min(dx, dy), colors=log_colormap(conc[i, j], *self.c_range_mg_m3)),
        )

    def puffs(self, t: float, puffs_k4: np.ndarray) -> None:
        """Plume puffs: (K, 4) rows of x, y, z [m, NED] and r^2 [m^2]; drawn with radius r."""
        p = np.asarray(puffs_k4, dtype=float).reshape(-1, 4)
        self._time(t)
        self.rec.log(
            "world/plume/puffs",
            rr.Points3D(p[:, :3], radii=np.sqrt(np.maximum(p[:, 3], 0.0)), colors=[(120, 170, 230, 60)]),
        )

    def wind_arrows(
        self,
        t: float,
        pos_ned: Sequence[float],
        wind_true_ned: Sequence[float] | None,
        wind_est_ned: Sequence[float] | None = None,
    ) -> None:
        """Wind at the vehicle as arrows from ``pos_ned`` [m]: true and estimated air-mass
        velocity [m/s, NED], i.e. pointing where the air goes, ``arrow_scale_s`` m per m/s."""
        t = float(t)
        origin = np.array(pos_ned, dtype=float)  # a copy: buffered, and callers pass live views
        for entity, w in (("world/wind/truth", wind_true_ned), ("world/wind/estimate", wind_est_ned)):
            if w is not None:
                vec = np.asarray(w, dtype=float) * self.arrow_scale_s
                self._push_row(entity, rr.Arrows3D, t, origins=origin, vectors=vec)
        self._maybe_flush(t)

    def geofence(self, min_ned: Sequence[float], max_ned: Sequence[float]) -> None:
        """Geofence box between the NED corners ``min_ned`` and ``max_ned`` [m] (static)."""
        lo = np.asarray(min_ned, dtype=float)
        hi = np.asarray(max_ned, dtype=float)
        self.rec.log(
            "world/geofence",
            rr.Boxes3D(mins=[lo], sizes=[hi - lo], colors=[(200, 60, 60)], labels=["geofence"]),
            static=True,
        )

    # ------------------------------------------------------------------ time series
    def wind(
        self,
        t: float,
        truth_ned: Sequence[float] | None = None,
        est_ned: Sequence[float] | None = None,
        sigma_ned: Sequence[float] | None = None,
    ) -> None:
        """Wind per NED axis [m/s]: truth, estimate, and the estimate +- 2 sigma band
        (``sigma_ned`` is the 1-sigma standard deviation per axis, needs ``est_ned``)."""
        t = float(t)
        for k, a in enumerate(AXES):
            if truth_ned is not None:
                self._push(f"wind/{a}/truth", t, truth_ned[k])
            if est_ned is not None:
                e = float(est_ned[k])
                self._push(f"wind/{a}/estimate", t, e)
                if sigma_ned is not None:
                    s = 2.0 * float(sigma_ned[k])
                    self._push(f"wind/{a}/lower", t, e - s)
                    self._push(f"wind/{a}/upper", t, e + s)
        self._maybe_flush(t)

    def wind_speed_dir(
        self,
        t: float,
        speed_raw: float | None,
        dir_raw_deg: float | None,
        speed_filt: float | None = None,
        dir_filt_deg: float | None = None,
        truth_speed: float | None = None,
        truth_dir_deg: float | None = None,
    ) -> None:
        """Horizontal wind speed [m/s] and from-direction [deg, 0 = from north, 90 = from east]:
        raw (per-sample) estimate, filtered estimate and truth; directions wrapped to [0, 360)."""
        t = float(t)
        for name, v in (("raw", speed_raw), ("filtered", speed_filt), ("truth", truth_speed)):
            self._push(f"wind/speed/{name}", t, v)
        for name, v in (("raw", dir_raw_deg), ("filtered", dir_filt_deg), ("truth", truth_dir_deg)):
            self._push(f"wind/direction/{name}", t, None if v is None else float(v) % 360.0)
        self._maybe_flush(t)

    def chem(self, t: float, value_mg_m3: float, threshold_mg_m3: float | None = None) -> None:
        """Chemical sensor reading and the strategy's detection threshold [mg/m^3]."""
        t = float(t)
        self._push("chem/value", t, value_mg_m3)
        self._push("chem/threshold", t, threshold_mg_m3)
        self._maybe_flush(t)

    def rotors(self, t: float, rad_s_4: Sequence[float]) -> None:
        """Rotor speeds [rad/s], rotors 1-4 in the vehicle file's order."""
        t = float(t)
        for i in range(4):
            self._push(f"rotors/{i + 1}", t, rad_s_4[i])
        self._maybe_flush(t)

    def scalar(self, t: float, name: str, value: float) -> None:
        """Any other scalar series, at ``extra/<name>`` (units in the name, e.g. "nis", "tilt_deg")."""
        t = float(t)
        self._push(f"extra/{name}", t, value)
        self._maybe_flush(t)

    def text(self, t: float, text: str, level: str = "INFO", channel: str = "events") -> None:
        """A text event (mode change, strategy state) at ``log/<channel>``; level one of TEXT_LEVELS."""
        level = level.upper()
        if level not in TEXT_LEVELS:
            raise ValueError(f"level = {level!r}: allowed values are {', '.join(TEXT_LEVELS)}")
        self._time(t)
        self.rec.log(f"log/{channel}", rr.TextLog(text, level=level))

    # ------------------------------------------------------------------ end
    def close(self) -> None:
        """Send everything buffered (series, last trail) and close the file. Idempotent."""
        if self._closed:
            return
        self.flush_series()
        if self._trail_dirty:
            self._time(self._t_last)
            self._send_trail()
        self.rec.flush()
        self.rec.disconnect()
        self._closed = True

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


__all__ = ["AXES", "TEXT_LEVELS", "TIMELINE", "RunRecorder", "log_colormap", "make_blueprint"]
