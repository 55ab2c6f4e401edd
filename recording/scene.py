"""The two spatial views of a recording: the plan-view map (``map/...``) and the 3D world (``world/...``).

The map is drawn north up: a NED point (n, e) is map point (x, y) = (e, -n) (the 2D view's y axis
points down). The 3D world is NED itself with ``ViewCoordinates.FRD`` (the viewer then knows -z is
up). Markers, paths and arrows use radii in UI points, so they keep their size on screen whatever
the scene's extent; the plume is drawn as a concentration field on a light-to-dark colour map
(an image transparent below the colour scale's low end on the map, the vertical slice along the wind
as small dots in 3D), never over the path.

Entity paths::

    map/plume                          concentration at flight altitude (an image)
    world/plume/curtain                concentration on the vertical plane along the wind through the source
    world/plume/puffs                  puff centres (small dots; off unless a caller logs them)
    map/posterior/{image,credible}     a strategy's source posterior (an indexed PNG) and its credible circle
    map/setpoint, world/setpoint       the position setpoint the mission sent (the mission's recording)
    map/path, world/trail              the path, one segment per row (on the map coloured by strategy
                                       state); the views show every row up to the time cursor
    map/hits                           where the sensor detected the plume, coloured by concentration (the same)
    map/vehicle, world/vehicle         the vehicle (Transform3D pose in 3D, with body, marker and axes)
    map/wind/*, world/wind/*           wind at the vehicle: truth and estimate (air-mass velocity)
    map/sources/*, world/sources/*     true source(s) and found radius, declared source and credible region
                                       (labels on their own points: .../label)
    map/geofence, world/geofence       the geofence outline
    map/north, map/scale, map/colorbar, world/north   north arrow, scale bar, concentration colour bar

An urban scenario adds its buildings and mean wind field (``map/buildings/*``, ``world/buildings``,
``map/wind_field/*``, ``world/wind_field/*``): :mod:`recording.urban_scene`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import rerun as rr

from recording.png import posterior_archetype
from recording.stream import RecorderBase
from recording.style import (
    C_DECLARED,
    C_EST,
    C_FENCE,
    C_FURNITURE,
    C_MAP_EST,
    C_MAP_TRUTH,
    C_POSTERIOR,
    C_SOURCE,
    C_TRAIL_3D,
    C_TRUTH,
    C_VEHICLE,
    VecLike,
    conc_image,
    log_colormap,
    state_color,
)
from recording.summary import FOUND_RADIUS_M

Bounds = tuple[float, float, float, float]  # north min, north max, east min, east max [m]
#: Where the true source's label sits in 3D relative to it (NED, m: above); the declared one's the opposite.
LABEL_OFFSET_3D = np.array([0.0, 0.0, -4.0])
#: Radius of the declared source's marker [UI points]: above the vehicle's (5) and the true source's (6).
DECLARED_PT = 8.0


def ui(px: float) -> float:
    """A radius in UI points (constant on screen), as rerun encodes it."""
    return -abs(float(px))  # rr.Radius.ui_points: a negative radius is in UI points


def to_map(ne: np.ndarray) -> np.ndarray:
    """NED (..., >= 2) -> map (..., 2) = (east, -north)."""
    a = np.asarray(ne, dtype=float)
    return np.stack([a[..., 1], -a[..., 0]], axis=-1)


def circle(center_ne: VecLike, r: float, n: int = 72) -> np.ndarray:
    """A closed circle of radius ``r`` [m] about (north, east), in map coordinates (n + 1, 2)."""
    a = np.linspace(0.0, 2.0 * math.pi, n + 1)
    return to_map(np.column_stack([center_ne[0] + r * np.cos(a), center_ne[1] + r * np.sin(a)]))


def nice_length(span: float) -> float:
    """A round length (1, 2 or 5 x 10^k m) of about a fifth of ``span``."""
    target = max(span / 5.0, 1e-3)
    k = 10.0 ** math.floor(math.log10(target))
    return min((1.0, 2.0, 5.0, 10.0), key=lambda m: abs(m * k - target)) * k


class SceneMixin(RecorderBase):
    """Map and 3D geometry (see the module docstring). Needs ``c_range_mg_m3`` and ``arrow_scale_s``."""

    c_range_mg_m3: tuple[float, float]
    arrow_scale_s: float
    trail_min_step_m: float
    #: A posterior and the urban layers' static images as PNGs (``rr.EncodedImage``), else raw RGBA
    #: (``rr.Image``): the same pixels (:mod:`recording.png`).
    png_images: bool = True

    def _init_scene(self) -> None:
        # The last path point and its state; the extent of the whole path (the map's bounds).
        self._path_last: np.ndarray | None = None
        self._path_last_state = ""
        self._path_lo = np.full(2, math.inf)
        self._path_hi = np.full(2, -math.inf)
        self._last_pos: np.ndarray | None = None
        self.path_state = "ground"
        self.scene_points: list[np.ndarray] = []  # (north, east) that must be on the map
        self.geofence_ne: Bounds | None = None
        self.flight_altitude_m = 5.0
        self._plume_grid: tuple[float, float, float, float] | None = None
        log = self.log_static
        log("world", rr.ViewCoordinates.FRD)  # NED = forward-right-down with forward = north
        log("world/vehicle/body", rr.Boxes3D(half_sizes=[[0.35, 0.35, 0.06]], colors=[(90, 90, 90)],
                                              fill_mode="MajorWireframe"))  # fmt: skip
        log("world/vehicle/marker", rr.Points3D([[0.0, 0.0, 0.0]], radii=ui(5.0), colors=[C_VEHICLE]))
        log("world/vehicle/axes", rr.Arrows3D(origins=np.zeros((3, 3)), vectors=np.eye(3) * 0.6,
                                               colors=[(230, 40, 40), (40, 180, 40), (40, 80, 230)]))  # fmt: skip
        log("map/vehicle", rr.Points2D.from_fields(radii=ui(5.0), colors=[C_VEHICLE], draw_order=30.0))
        log("map/path", rr.LineStrips2D.from_fields(radii=ui(1.5), draw_order=10.0))
        # Hits under the path: the dots show beside the line, the line's state colour stays visible.
        log("map/hits", rr.Points2D.from_fields(radii=ui(2.5), draw_order=9.0))
        log("world/trail", rr.LineStrips3D.from_fields(radii=ui(1.5), colors=[C_TRAIL_3D]))
        for name, c, cm in (("truth", C_TRUTH, C_MAP_TRUTH), ("estimate", C_EST, C_MAP_EST)):
            log(f"world/wind/{name}", rr.Arrows3D.from_fields(colors=[c], radii=ui(1.5)))
            log(f"map/wind/{name}", rr.Arrows2D.from_fields(colors=[cm], radii=ui(2.2), draw_order=25.0))

    # ------------------------------------------------------------------ extent
    def set_scene(self, points_ne: Sequence[VecLike] | np.ndarray, altitude_m: float | None = None) -> None:
        """Points (north, east) [m] the map must show (start, sources), and the flight altitude [m]."""
        for p in points_ne:
            self.scene_points.append(np.asarray(p, dtype=float)[:2])
        if altitude_m is not None and altitude_m > 0:
            self.flight_altitude_m = float(altitude_m)
        self.send_furniture(self.scene_bounds())

    def scene_bounds(self, margin_frac: float = 0.12, min_margin_m: float = 8.0, aspect: float = 1.4) -> Bounds:
        """The map's extent: the path, the start, the sources and the declaration, with a margin,
        widened to ``aspect`` (east span over north span, or the reverse: room for the map's
        furniture in the corners), inside the geofence (so puffs far downwind or the fence itself
        never set the view)."""
        pts = list(self.scene_points)
        if np.all(np.isfinite(self._path_lo)):
            pts += [self._path_lo, self._path_hi]
        a = np.array(pts) if pts else np.zeros((1, 2))
        lo, hi = a.min(axis=0), a.max(axis=0)
        m = max(min_margin_m, margin_frac * float(max(hi - lo)))
        lo, hi = lo - m, hi + m
        sn, se = hi - lo
        if se < sn * aspect:  # tall: widen east-west (the map panel is wider than tall)
            c = 0.5 * (lo[1] + hi[1])
            lo[1], hi[1] = c - 0.5 * sn * aspect, c + 0.5 * sn * aspect
        elif sn < se / aspect / 1.5:  # very flat: heighten north-south a little
            c = 0.5 * (lo[0] + hi[0])
            lo[0], hi[0] = c - 0.5 * se / aspect / 1.5, c + 0.5 * se / aspect / 1.5
        n0, n1, e0, e1 = lo[0], hi[0], lo[1], hi[1]
        if self.geofence_ne is not None:
            g = self.geofence_ne
            cut = max(n0, g[0]), min(n1, g[1]), max(e0, g[2]), min(e1, g[3])
            if cut[1] - cut[0] >= min_margin_m and cut[3] - cut[2] >= min_margin_m:  # else a fence elsewhere: ignored
                n0, n1, e0, e1 = cut
        return float(n0), float(n1), float(e0), float(e1)

    def send_furniture(self, b: Bounds) -> None:
        """North arrow and scale bar (with the wind arrows' scale) in the map's top-left corner, the
        concentration colour bar in its top-right corner, a north arrow in 3D."""
        n0, n1, e0, e1 = b
        span = min(n1 - n0, e1 - e0)
        length = nice_length(span)
        pad = 0.05 * span
        x0, y0 = e0 + pad, -n1 + pad  # top-left corner of the map
        log = self.log_static
        log("map/north", rr.Arrows2D(origins=[[x0, y0 + 0.2 * span]], vectors=[[0.0, -0.14 * span]],
                                     colors=[C_FURNITURE], radii=ui(2.0), draw_order=40.0))  # fmt: skip
        self._label("map/north/label", (x0, y0 + 0.02 * span), "N")
        wind = length / self.arrow_scale_s
        y_bar = y0 + 0.28 * span
        log("map/scale", rr.LineStrips2D([[[x0, y_bar], [x0 + length, y_bar]]], colors=[C_FURNITURE], radii=ui(2.0),
                                         draw_order=40.0))  # fmt: skip
        self._label("map/scale/label", (x0 + 0.5 * length, y_bar + 0.04 * span),
                    f"{length:g} m; wind arrows: {wind:g} m/s")
        lo, hi = self.c_range_mg_m3
        decades = np.arange(math.ceil(math.log10(lo) - 1e-9), math.floor(math.log10(hi) + 1e-9) + 1)
        c = 10.0 ** decades[::-1]  # top = high
        h = 0.07 * span
        x_bar = e1 - pad - h
        rgba = np.concatenate([log_colormap(c, lo, hi), np.full((len(c), 1), 255, dtype=np.uint8)], axis=1)
        # The image's transform applies to its children too: the labels are its siblings.
        log("map/colorbar/image", rr.Transform3D(translation=[x_bar, y0, 0.0], scale=[h, h, 1.0]))
        log("map/colorbar/image", rr.Image(rgba.reshape(len(c), 1, 4), draw_order=39.0))
        # Short labels left of the bar (the viewer centres a label on its point: on the bar, the labels'
        # boxes hid its colours), the unit under it.
        self._label("map/colorbar/labels", [(x_bar - 0.8 * h, y0 + h * (i + 0.5)) for i in range(len(c))],
                    [f"{v:g}" for v in c])  # fmt: skip
        self._label("map/colorbar/unit", (x_bar + 0.5 * h, y0 + h * (len(c) + 0.6)), "mg/m³")
        log("world/north", rr.Arrows3D(origins=[[n0 + pad, e0 + pad, 0.0]], vectors=[[0.15 * span, 0.0, 0.0]],
                                       labels=["N"], colors=[C_FURNITURE], radii=ui(2.0)))  # fmt: skip

    def _label(self, entity: str, xy: VecLike | Sequence[VecLike] | np.ndarray, text: str | list[str]) -> None:
        """Dark labels at map points (the points themselves too small to see): the viewer draws a label
        centred on its point, so a label beside a marker needs its own point."""
        pts = np.asarray(xy, dtype=float).reshape(-1, 2)
        texts = [text] if isinstance(text, str) else list(text)
        self.log_static(entity, rr.Points2D(pts, radii=ui(0.1), colors=[C_FURNITURE], labels=texts, draw_order=41.0))

    # ------------------------------------------------------------------ vehicle and path
    def vehicle(self, t: float, pos_ned: VecLike, quat_wxyz: VecLike) -> None:
        """Vehicle pose: position [m, NED] and attitude quaternion [w, x, y, z] (body FRD -> NED).

        Also extends the path: a segment whenever the vehicle moved ``trail_min_step_m`` or
        ``path_state`` changed (its colour on the map)."""
        t = float(t)
        # Copies: callers pass views of live state (sim.x[0:3]) and rows are sent later.
        p = np.array(pos_ned, dtype=float)
        q = np.array(quat_wxyz, dtype=float)
        self._last_pos = p
        self._push_row("world/vehicle", rr.Transform3D, t, translation=p, quaternion=(q[1], q[2], q[3], q[0]))
        self._push_row("map/vehicle", rr.Points2D, t, positions=(p[1], -p[0]))
        last = self._path_last
        if last is None:
            self._path_last, self._path_last_state = p, self.path_state
        elif math.dist(p, last) >= self.trail_min_step_m or self.path_state != self._path_last_state:
            # One segment per row, sent with the buffered columns: the views show every row up to
            # the time cursor (recording.layout), so the path is whole and current at any time.
            rgb = state_color(self.path_state)
            self._push_row("map/path", rr.LineStrips2D, t, strips=((last[1], -last[0]), (p[1], -p[0])), colors=rgb)
            self._push_row("world/trail", rr.LineStrips3D, t, strips=(last, p))
            self._path_last, self._path_last_state = p, self.path_state
            self._path_lo = np.minimum(self._path_lo, p[:2])
            self._path_hi = np.maximum(self._path_hi, p[:2])
        self._maybe_flush(t)

    def _hit(self, value_mg_m3: float) -> None:
        """A detection at the vehicle's latest position: a dot on the map, coloured by concentration
        (one row per hit, shown like the path: every row up to the time cursor)."""
        if self._last_pos is not None:
            p = self._last_pos
            # The row keeps the concentration; the colours of a batch of hits are mapped when it is sent.
            self._buffer("map/hits", rr.Points2D, convert={"colors": self._conc_colors})
            self._push_row("map/hits", rr.Points2D, self.t_latest, positions=(p[1], -p[0]), colors=value_mg_m3)

    def _conc_colors(self, c: np.ndarray) -> np.ndarray:
        return log_colormap(c, *self.c_range_mg_m3)

    # ------------------------------------------------------------------ sources
    def true_sources(self, sources_ned: Sequence[VecLike] | np.ndarray) -> None:
        """True source positions [m, NED] (static), with the found radius drawn around each."""
        true = np.asarray(sources_ned, dtype=float).reshape(-1, 3)
        if not len(true):
            return
        self.scene_points += [s[:2] for s in true]
        labels = ["source" if len(true) == 1 else f"source {i + 1}" for i in range(len(true))]
        # 3D labels on their own points, the true source's above and the declared one's below (the
        # viewer centres a label on its point: a declaration a few metres off hid the other label).
        self.log_static("world/sources/true", rr.Points3D(true, radii=ui(6.0), colors=[C_SOURCE]))
        self.log_static("world/sources/true/label", rr.Points3D(true + LABEL_OFFSET_3D, radii=ui(0.1),
                                                                colors=[C_SOURCE], labels=labels))  # fmt: skip
        self.log_static("map/sources/true", rr.Points2D(to_map(true), radii=ui(6.0), colors=[C_SOURCE],
                                                        draw_order=20.0))  # fmt: skip
        off = np.array([0.0, -(FOUND_RADIUS_M + 3.0)])  # above the found circle
        self.log_static("map/sources/true/label", rr.Points2D(to_map(true) + off, radii=ui(0.1), colors=[C_SOURCE],
                                                              labels=labels, draw_order=41.0))  # fmt: skip
        self.log_static("map/sources/found_radius", rr.LineStrips2D([circle(s, FOUND_RADIUS_M) for s in true],
                                                                    colors=[C_SOURCE], radii=ui(1.0),
                                                                    draw_order=19.0))  # fmt: skip

    def declared(self, t: float, ned: VecLike, confidence: float | None = None,
                 credible_radius_m: float | None = None) -> None:  # fmt: skip
        """The declared source [m, NED] at vehicle time ``t`` [s], its confidence (0..1) and, when the
        strategy gives one, the radius of its credible region [m]."""
        d = np.asarray(ned, dtype=float).reshape(1, 3)
        self.scene_points.append(d[0, :2])
        label = "declared" if confidence is None else f"declared {100.0 * float(confidence):.0f}%"
        # Larger than the vehicle's marker (5 pt) and drawn over it and the wind arrows on the map, on a
        # white halo: a declaration right at the vehicle (it declares where it is) stays visible.
        self.log_at(t, "world/sources/declared", rr.Points3D(d, radii=ui(DECLARED_PT), colors=[C_DECLARED]))
        self.log_at(t, "world/sources/declared/label", rr.Points3D(d - LABEL_OFFSET_3D, radii=ui(0.1),
                                                                   colors=[C_DECLARED], labels=[label]))  # fmt: skip
        self.log_at(t, "map/sources/declared/halo", rr.Points2D(to_map(d), radii=ui(DECLARED_PT + 2.5),
                                                                colors=[(255, 255, 255)], draw_order=44.0))  # fmt: skip
        self.log_at(t, "map/sources/declared", rr.Points2D(to_map(d), radii=ui(DECLARED_PT), colors=[C_DECLARED],
                                                           draw_order=45.0))  # fmt: skip
        self.log_at(t, "map/sources/declared/label", rr.Points2D(to_map(d) + np.array([0.0, FOUND_RADIUS_M + 3.0]),
                                                                 radii=ui(0.1), colors=[C_DECLARED], labels=[label],
                                                                 draw_order=41.0))  # fmt: skip
        if credible_radius_m is not None and math.isfinite(credible_radius_m) and credible_radius_m > 0:
            self.log_at(t, "map/sources/credible", rr.LineStrips2D([circle(d[0], credible_radius_m)],
                                                                   colors=[C_DECLARED], radii=ui(1.5),
                                                                   labels=[f"{credible_radius_m:.1f} m"],
                                                                   draw_order=21.0))  # fmt: skip

    def geofence(self, min_ned: VecLike, max_ned: VecLike) -> None:
        """Geofence box between the NED corners ``min_ned`` and ``max_ned`` [m] (static outline)."""
        lo = np.asarray(min_ned, dtype=float)
        hi = np.asarray(max_ned, dtype=float)
        self.geofence_ne = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
        ring = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]], [lo[0], lo[1]]])
        self.log_static("map/geofence", rr.LineStrips2D([to_map(ring)], colors=[C_FENCE], radii=ui(1.0),
                                                        draw_order=1.0))  # fmt: skip
        self.log_static("world/geofence", rr.LineStrips3D([np.column_stack([ring, np.zeros(len(ring))])],
                                                          colors=[C_FENCE], radii=ui(1.0)))  # fmt: skip

    # ------------------------------------------------------------------ plume and posterior
    def plume_slice(self, t: float, xs: np.ndarray, ys: np.ndarray, C: np.ndarray, z: float) -> None:
        """Horizontal concentration slice at NED depth ``z`` [m]: ``C[i, j]`` [mg/m^3] at (``xs[i]``
        north, ``ys[j]`` east) on a regular grid (``sitl.world.plume.*.slice_grid``'s layout), drawn
        on the map as an image (transparent below the colour scale's low end). The 3D view shows the
        vertical slice instead (:meth:`plume_curtain`): the map already shows this one."""
        xs = np.asarray(xs, dtype=float)
        ys = np.asarray(ys, dtype=float)
        conc = np.asarray(C, dtype=float).reshape(len(xs), len(ys))
        dx = float(xs[1] - xs[0]) if len(xs) > 1 else 1.0
        dy = float(ys[1] - ys[0]) if len(ys) > 1 else 1.0
        grid = (float(xs[-1]), float(ys[0]), dx, dy)
        self._time(t)
        if grid != self._plume_grid:  # the image's pixel (0, 0) is the north-west cell
            self._plume_grid = grid
            self.rec.log("map/plume", rr.Transform3D(translation=[ys[0] - 0.5 * dy, -(xs[-1] + 0.5 * dx), 0.0],
                                                     scale=[dy, dx, 1.0]))  # fmt: skip
        # Opacity below 1: the viewer then blends by the alpha channel (at 1 it draws the image opaque).
        self.rec.log("map/plume", rr.Image(conc_image(conc, *self.c_range_mg_m3), opacity=0.99, draw_order=-10.0))

    def plume_curtain(self, t: float, origin_ne: VecLike, dir_ne: VecLike, s: np.ndarray,
                      z: np.ndarray, C: np.ndarray) -> None:  # fmt: skip
        """Vertical concentration slice: ``C[i, j]`` [mg/m^3] at horizontal point ``origin_ne + s[i] *
        dir_ne`` [m] and NED depth ``z[j]`` [m] (``dir_ne`` a unit vector, e.g. downwind); 3D dots."""
        s = np.asarray(s, dtype=float)
        z = np.asarray(z, dtype=float)
        conc = np.asarray(C, dtype=float).reshape(len(s), len(z))
        i, j = np.nonzero(conc >= self.c_range_mg_m3[0])
        o, d = np.asarray(origin_ne, dtype=float), np.asarray(dir_ne, dtype=float)
        pts = np.column_stack([o[0] + s[i] * d[0], o[1] + s[i] * d[1], z[j]])
        ds = float(np.min(np.diff(s))) if len(s) > 1 else 1.0
        self.log_at(t, "world/plume/curtain", rr.Points3D(pts, radii=0.15 * ds,
                                                          colors=log_colormap(conc[i, j], *self.c_range_mg_m3)))

    def puffs(self, t: float, puffs_k4: np.ndarray) -> None:
        """Plume puffs: (K, 4) rows of x, y, z [m, NED] and r^2 [m^2]; their centres as small light dots
        (only those over the map's extent: puffs drift hundreds of metres downwind)."""
        p = np.asarray(puffs_k4, dtype=float).reshape(-1, 4)
        n0, n1, e0, e1 = self.scene_bounds()
        keep = (p[:, 0] >= n0) & (p[:, 0] <= n1) & (p[:, 1] >= e0) & (p[:, 1] <= e1)
        self.log_at(t, "world/plume/puffs", rr.Points3D(p[keep, :3], radii=ui(1.5), colors=[(150, 190, 235)]))

    def posterior(self, t: float, p_ne: np.ndarray, extent_ne: VecLike,
                  credible: tuple[VecLike, float] | None = None) -> None:  # fmt: skip
        """A strategy's source posterior on the map at vehicle time ``t`` [s].

        ``p_ne[i, j]`` is the probability of cell i (north) x j (east) of the grid spanning
        ``extent_ne`` = (north_min, north_max, east_min, east_max) [m NED] (what
        ``posterior_map()`` of a probabilistic strategy returns); drawn purple, opacity by
        probability relative to the grid's maximum. ``credible`` = (centre (north, east) [m],
        radius [m]) draws the credible region's circle.
        """
        p = np.asarray(p_ne, dtype=float)
        if p.ndim != 2 or not p.size:
            raise ValueError(f"posterior: expected a 2D grid, got shape {p.shape}")
        n0, n1, e0, e1 = (float(v) for v in extent_ne)
        if not (n1 > n0 and e1 > e0):
            raise ValueError(f"posterior: extent {tuple(extent_ne)} must be (north_min, north_max, east_min, east_max)")
        p, (n0, n1, e0, e1) = _visible_part(p, (n0, n1, e0, e1))
        self._time(t)
        place = rr.Transform3D(translation=[e0, -n1, 0.0], scale=[(e1 - e0) / p.shape[1], (n1 - n0) / p.shape[0], 1.0])
        # One row (one chunk in the file, not two); a PNG: the same pixels in less than half the bytes.
        self.rec.log("map/posterior/image", place, posterior_archetype(p, self.png_images))
        if credible is not None and math.isfinite(credible[1]) and credible[1] > 0:
            c, r = credible
            self.rec.log("map/posterior/credible", rr.LineStrips2D([circle(c, r)], colors=[C_POSTERIOR], radii=ui(1.5),
                                                                   labels=[f"credible {r:.1f} m"], draw_order=22.0))
        else:
            self.rec.log("map/posterior/credible", rr.Clear(recursive=False))

    def setpoint(self, t: float, pos_ned: VecLike) -> None:
        """The position setpoint [m, NED] a mission sent at vehicle time ``t`` [s] (a row on the map and in 3D;
        the style is the caller's, :mod:`recording.mission_rrd`)."""
        p = np.array(pos_ned, dtype=float)  # a copy: rows are sent later
        self._push_row("map/setpoint", rr.Points2D, t, positions=(p[1], -p[0]))
        self._push_row("world/setpoint", rr.Points3D, t, positions=p)
        self._maybe_flush(float(t))

    # ------------------------------------------------------------------ wind
    def wind_arrows(self, t: float, pos_ned: VecLike, wind_true_ned: VecLike | None,
                    wind_est_ned: VecLike | None = None) -> None:  # fmt: skip
        """Wind at the vehicle as arrows from ``pos_ned`` [m]: true and estimated air-mass velocity
        [m/s, NED] (pointing where the air goes), ``arrow_scale_s`` metres per m/s, in 3D and on the map."""
        t = float(t)
        origin = np.array(pos_ned, dtype=float)  # a copy: buffered, and callers pass live views
        for name, w in (("truth", wind_true_ned), ("estimate", wind_est_ned)):
            if w is not None:
                vec = np.asarray(w, dtype=float) * self.arrow_scale_s
                self._push_row(f"world/wind/{name}", rr.Arrows3D, t, origins=origin, vectors=vec)
                self._push_row(f"map/wind/{name}", rr.Arrows2D, t, origins=(origin[1], -origin[0]),
                               vectors=(vec[1], -vec[0]))  # fmt: skip
        self._maybe_flush(t)


__all__ = ["Bounds", "SceneMixin", "circle", "nice_length", "to_map", "ui"]


def _visible_part(p: np.ndarray, extent: tuple[float, float, float, float]) -> tuple[np.ndarray, tuple[float, ...]]:
    """The smallest sub-grid (and its extent, m) holding every cell :func:`posterior_image` draws visibly
    (opacity >= 1 of 255: p >= max x (0.5 / 190)^2). A particle posterior fills a few hundred cells of a
    ~430 x 430 grid; drawing only those cuts the image's cost and the file (the mission logs it every second
    while it flies), and the picture is the same."""
    top = float(np.max(p))
    if not (top > 0.0 and math.isfinite(top)):
        return p, extent
    keep = p >= top * POSTERIOR_VISIBLE
    rows, cols = np.flatnonzero(keep.any(axis=1)), np.flatnonzero(keep.any(axis=0))
    n0, n1, e0, e1 = extent
    dn, de = (n1 - n0) / p.shape[0], (e1 - e0) / p.shape[1]
    i0, i1, j0, j1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    return p[i0:i1, j0:j1], (n0 + i0 * dn, n0 + i1 * dn, e0 + j0 * de, e0 + j1 * de)


#: Relative probability under which :func:`recording.style.posterior_image` draws a cell fully transparent.
POSTERIOR_VISIBLE = (0.5 / 190.0) ** 2
