"""Urban layers of a recording (issue 20): buildings and the mean wind field among them, static.

Logged once, only for a scenario with buildings (an open-field recording gains nothing):

    map/buildings/fill                 footprints: translucent warm-grey fill (an image) ...
    map/buildings/outline              ... dark outlines (one closed strip per building)
    map/buildings/label                name and roof height at each footprint's centre
    world/buildings                    the buildings as translucent solid boxes (rectangular footprints)
    world/buildings/outline            their edges (wireframe boxes); other footprints: walls as a mesh
    map/wind_field/speed               mean wind speed at flight altitude (an image, colour scale below)
    map/wind_field/arrows              mean wind at flight altitude, an arrow every few metres (length
                                       by speed: the longest arrow is ``FIELD_ARROW_FILL`` of the spacing)
    map/wind_field/section             the trace of the vertical section on the map, labelled
    map/wind_field/colorbar/*          the speed colour bar (m/s) in the map's bottom-right corner
    world/wind_field/section           mean wind speed on the vertical plane along the wind through the
                                       source (a translucent mesh, the same colours)
    world/wind_field/section/arrows    the in-plane wind on that plane (along-wind and vertical parts)

The map shows the horizontal slice and the 3D view the vertical section (as for the plume: in 3D a
horizontal plane at flight altitude would cut through the path). Speeds share one linear colour
scale from 0 to ``wind_vmax_m_s`` (:func:`recording.style.speed_colormap`). Units m, m/s; NED; the
map's (x, y) = (east, -north) (:func:`recording.scene.to_map`); heights above the ground (z = 0).
Draw order on the map: wind speed -20, arrows -12, plume -10, buildings -8, posterior -5, path 10.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import rerun as rr

from recording.png import image_archetype
from recording.scene import Bounds, SceneMixin, to_map, ui
from recording.style import (
    C_BUILDING,
    C_BUILDING_EDGE,
    C_BUILDING_MAP,
    C_FIELD_ARROW,
    C_FURNITURE,
    SCENE_BACKGROUND,
    speed_colormap,
)

#: Buildings this close to the start / sources' box [m] set the map's extent too.
BUILDINGS_NEAR_M = 60.0
#: The longest field arrow, as a fraction of the arrows' spacing.
FIELD_ARROW_FILL = 0.9
#: Map pixels of the building footprints' fill image per metre.
FOOTPRINT_PX_PER_M = 2.0
#: Opacity of the wind speed colours on the map (0-255) and of the 3D section (0-255).
WIND_MAP_ALPHA = 150
WIND_SECTION_ALPHA = 140


def rectangle(fp: np.ndarray) -> tuple[np.ndarray, float, float, float] | None:
    """(centre (2,), length, width [m], heading [rad]) of a rectangular footprint (4, 2) (north, east),
    the length along corner 0 -> 1, heading clockwise from north; None if it is no rectangle."""
    if fp.shape != (4, 2):
        return None
    a, b = fp[1] - fp[0], fp[3] - fp[0]
    la, lb = float(np.hypot(*a)), float(np.hypot(*b))
    if la <= 0 or lb <= 0 or abs(float(a @ b)) > 1e-6 * la * lb or not np.allclose(fp[2], fp[1] + b, atol=1e-6):
        return None
    return fp.mean(axis=0), la, lb, math.atan2(float(a[1]), float(a[0]))


def _inside_polygon(x: np.ndarray, y: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule: which points (x, y) lie inside the polygon (V, 2) (same coordinates)."""
    inside = np.zeros(x.shape, dtype=bool)
    px, py = poly[:, 0], poly[:, 1]
    for i in range(len(poly)):
        x0, y0, x1, y1 = px[i - 1], py[i - 1], px[i], py[i]
        if y0 == y1:
            continue
        cross = ((y0 > y) != (y1 > y)) & (x < x0 + (y - y0) * (x1 - x0) / (y1 - y0))
        inside ^= cross
    return inside


def nice_ceil(v: float) -> float:
    """The smallest of 1, 2, 2.5, 5 x 10^k at or above ``v`` (> 0)."""
    v = max(float(v), 1e-6)
    k = 10.0 ** math.floor(math.log10(v))
    return next(m * k for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * k >= v - 1e-12)


class UrbanSceneMixin(SceneMixin):
    """Buildings and the mean wind field on the map and in 3D (see the module docstring)."""

    wind_vmax_m_s: float | None = None
    top_m = 0.0  # the tallest building [m above the ground] (the 3D camera, recording.layout)

    def buildings(self, footprints_ne: Sequence[np.ndarray], heights_m: Sequence[float],
                  names: Sequence[str] | None = None) -> None:  # fmt: skip
        """Static buildings: footprints (V, 2) (north, east) [m], roof heights above the ground [m],
        names. Those within :data:`BUILDINGS_NEAR_M` of the start and sources (``set_scene`` /
        ``true_sources`` first) widen the map's extent."""
        fps = [np.asarray(f, dtype=float).reshape(-1, 2) for f in footprints_ne]
        hs = [float(h) for h in heights_m]
        if not fps:
            return
        names = list(names) if names is not None else [""] * len(fps)
        self.top_m = max(self.top_m, *hs)
        self._buildings_3d(fps, hs, names)
        self._buildings_map(fps, hs, names)
        near = np.array(self.scene_points) if self.scene_points else None
        for f in fps:
            c = f.mean(axis=0)
            if near is None or (np.all(c >= near.min(axis=0) - BUILDINGS_NEAR_M)
                                and np.all(c <= near.max(axis=0) + BUILDINGS_NEAR_M)):  # fmt: skip
                self.scene_points += list(f)
        self.send_furniture(self.scene_bounds())

    def _buildings_3d(self, fps: list[np.ndarray], hs: list[float], names: list[str]) -> None:
        boxes = [(rectangle(f), h, n) for f, h, n in zip(fps, hs, names, strict=True)]
        rect = [(r, h, n) for r, h, n in boxes if r is not None]
        if rect:
            centers = [[r[0][0], r[0][1], -0.5 * h] for r, h, _ in rect]
            half = [[0.5 * r[1], 0.5 * r[2], 0.5 * h] for r, h, _ in rect]
            rot = [rr.RotationAxisAngle(axis=[0.0, 0.0, 1.0], radians=r[3]) for r, _, _ in rect]  # about down: N -> E
            self.log_static("world/buildings", rr.Boxes3D(centers=centers, half_sizes=half, rotation_axis_angles=rot,
                                                          colors=[C_BUILDING], fill_mode="Solid",
                                                          labels=[n for _, _, n in rect], show_labels=False))
            self.log_static("world/buildings/outline", rr.Boxes3D(centers=centers, half_sizes=half,
                                                                  rotation_axis_angles=rot, colors=[C_BUILDING_EDGE],
                                                                  fill_mode="MajorWireframe", radii=ui(0.75)))
        other = [(f, h) for (r, h, _), f in zip(boxes, fps, strict=True) if r is None]
        if other:  # any other footprint: its walls as a mesh (the roof's outline shows its shape)
            verts: list[np.ndarray] = []
            tris: list[list[int]] = []
            strips: list[np.ndarray] = []
            for f, h in other:
                for i in range(len(f)):
                    a, b = f[i - 1], f[i]
                    k = 4 * len(verts)
                    verts.append(np.array([[a[0], a[1], 0.0], [b[0], b[1], 0.0], [b[0], b[1], -h], [a[0], a[1], -h]]))
                    tris += [[k, k + 1, k + 2], [k, k + 2, k + 3]]
                strips.append(np.column_stack([np.vstack([f, f[:1]]), np.full(len(f) + 1, -h)]))
            self.log_static("world/buildings/walls", rr.Mesh3D(vertex_positions=np.vstack(verts), triangle_indices=tris,
                                                               albedo_factor=C_BUILDING))  # fmt: skip
            self.log_static("world/buildings/roofs", rr.LineStrips3D(strips, colors=[C_BUILDING_EDGE], radii=ui(0.75)))

    def _buildings_map(self, fps: list[np.ndarray], hs: list[float], names: list[str]) -> None:
        allpts = np.vstack(fps)
        lo, hi = allpts.min(axis=0) - 1.0, allpts.max(axis=0) + 1.0
        px = 1.0 / FOOTPRINT_PX_PER_M
        n_n, n_e = int(math.ceil((hi[0] - lo[0]) / px)), int(math.ceil((hi[1] - lo[1]) / px))
        north = hi[0] - (np.arange(n_n) + 0.5) * px  # image row 0 = the northmost
        east = lo[1] + (np.arange(n_e) + 0.5) * px
        nn, ee = np.meshgrid(north, east, indexing="ij")
        mask = np.zeros(nn.shape, dtype=bool)
        for f in fps:
            mask |= _inside_polygon(nn, ee, f)
        rgba = np.zeros((*mask.shape, 4), dtype=np.uint8)
        rgba[mask] = C_BUILDING_MAP
        # Children of the image's entity would get its pixel scale: the outlines are siblings.
        self.log_static("map/buildings/fill", rr.Transform3D(translation=[lo[1], -hi[0], 0.0], scale=[px, px, 1.0]))
        self.log_static("map/buildings/fill", image_archetype(rgba, self.png_images, opacity=0.99, draw_order=-8.0))
        rings = [to_map(np.vstack([f, f[:1]])) for f in fps]
        self.log_static("map/buildings/outline", rr.LineStrips2D(rings, colors=[C_BUILDING_EDGE], radii=ui(1.0),
                                                                 draw_order=-7.0))  # fmt: skip
        labels = [f"{n} {h:g} m" if n else f"{h:g} m" for n, h in zip(names, hs, strict=True)]
        self.log_static("map/buildings/label", rr.Points2D(to_map(np.array([f.mean(axis=0) for f in fps])),
                                                           radii=ui(0.1), colors=[C_FURNITURE], labels=labels,
                                                           draw_order=41.0))  # fmt: skip

    # ------------------------------------------------------------------ the mean wind field
    def wind_field_slice(self, xs: np.ndarray, ys: np.ndarray, wind_ne: np.ndarray, altitude_m: float,
                         v_max: float | None = None, arrow_every: int = 4) -> None:  # fmt: skip
        """The mean wind at ``altitude_m`` above the ground on a regular grid: ``wind_ne[i, j]`` =
        (north, east) [m/s] at (``xs[i]`` north, ``ys[j]`` east) [m] (NaN inside a building: left
        transparent). Drawn on the map: speed as colours, an arrow every ``arrow_every`` cells."""
        xs, ys = np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)
        w = np.asarray(wind_ne, dtype=float).reshape(len(xs), len(ys), 2)
        speed = np.hypot(w[..., 0], w[..., 1])
        if v_max is None:
            v_max = nice_ceil(float(np.nanpercentile(speed, 99.0)) if np.isfinite(speed).any() else 1.0)
        self.wind_vmax_m_s = float(v_max)
        dx, dy = float(xs[1] - xs[0]), float(ys[1] - ys[0])
        img = np.zeros((len(xs), len(ys), 4), dtype=np.uint8)
        ok = np.isfinite(speed)
        img[ok, :3] = speed_colormap(speed[ok], v_max)
        img[ok, 3] = WIND_MAP_ALPHA
        corner = [ys[0] - 0.5 * dy, -(xs[-1] + 0.5 * dx), 0.0]  # the image's pixel (0, 0): the north-west cell
        self.log_static("map/wind_field/speed", rr.Transform3D(translation=corner, scale=[dy, dx, 1.0]))
        self.log_static("map/wind_field/speed", image_archetype(img[::-1], self.png_images, 0.99, -20.0))
        sub = (slice(arrow_every // 2, None, arrow_every),) * 2
        n, e = np.meshgrid(xs, ys, indexing="ij")
        keep = ok[sub] & (speed[sub] > 0.02 * v_max)
        scale = FIELD_ARROW_FILL * arrow_every * min(dx, dy) / v_max  # m of arrow per m/s
        origins = to_map(np.column_stack([n[sub][keep], e[sub][keep]]))
        vec = w[sub][keep] * scale
        self.log_static("map/wind_field/arrows", rr.Arrows2D(origins=origins - 0.5 * to_map(vec), vectors=to_map(vec),
                                                             colors=[C_FIELD_ARROW], radii=ui(0.6),
                                                             draw_order=-12.0))  # fmt: skip
        self.wind_field_altitude_m = float(altitude_m)
        self.send_furniture(self.scene_bounds())

    def wind_field_section(self, origin_ne: np.ndarray, dir_ne: np.ndarray, s: np.ndarray, h: np.ndarray,
                           along: np.ndarray, down: np.ndarray,
                           arrow_every: tuple[int, int] = (3, 3)) -> None:  # fmt: skip
        """The mean wind on the vertical plane through ``origin_ne`` along the unit vector ``dir_ne``
        (north, east): ``along[i, j]`` and ``down[i, j]`` [m/s] are its components along ``dir_ne``
        and down at (``origin_ne + s[i] * dir_ne``, height ``h[j]`` [m] above the ground), NaN inside a
        building. In 3D: speed colours on a translucent mesh, in-plane arrows; on the map: its trace."""
        s, h = np.asarray(s, dtype=float), np.asarray(h, dtype=float)
        a = np.asarray(along, dtype=float).reshape(len(s), len(h))
        d = np.asarray(down, dtype=float).reshape(len(s), len(h))
        o, u = np.asarray(origin_ne, dtype=float)[:2], np.asarray(dir_ne, dtype=float)[:2]
        speed = np.hypot(a, d)
        v_max = self.wind_vmax_m_s or nice_ceil(float(np.nanpercentile(speed, 99.0)))
        ss, hh = np.meshgrid(s, h, indexing="ij")
        pts = np.column_stack([o[0] + ss.ravel() * u[0], o[1] + ss.ravel() * u[1], -hh.ravel()])
        ok = np.isfinite(speed)
        ns, nh = len(s), len(h)
        ii, jj = np.meshgrid(np.arange(ns - 1), np.arange(nh - 1), indexing="ij")
        cell_ok = (ok[:-1, :-1] & ok[1:, :-1] & ok[:-1, 1:] & ok[1:, 1:]).ravel()
        k = (ii * nh + jj).ravel()[cell_ok]
        tris = np.vstack([np.column_stack([k, k + nh, k + nh + 1]), np.column_stack([k, k + nh + 1, k + 1])])
        colors = speed_colormap(np.nan_to_num(speed.ravel()), v_max)
        self.log_static("world/wind_field/section", rr.Mesh3D(vertex_positions=pts, triangle_indices=tris,
                                                              vertex_colors=colors,
                                                              albedo_factor=(255, 255, 255, WIND_SECTION_ALPHA)))
        step_s, step_h = arrow_every
        sub = (slice(step_s // 2, None, step_s), slice(step_h // 2, None, step_h))
        keep = ok[sub] & (speed[sub] > 0.02 * v_max)
        ds = float(np.min(np.diff(s))) if ns > 1 else 1.0
        scale = FIELD_ARROW_FILL * step_s * ds / v_max
        vec = np.column_stack([a[sub][keep] * u[0], a[sub][keep] * u[1], d[sub][keep]]) * scale
        base = pts.reshape(ns, nh, 3)[sub][keep]
        self.log_static("world/wind_field/section/arrows", rr.Arrows3D(origins=base - 0.5 * vec, vectors=vec,
                                                                       colors=[C_FIELD_ARROW], radii=ui(0.8)))
        ends = np.array([o + s[0] * u, o + s[-1] * u])
        self.log_static("map/wind_field/section", rr.LineStrips2D([to_map(ends)], colors=[C_FIELD_ARROW],
                                                                  radii=ui(0.8), draw_order=-6.0))  # fmt: skip
        # Labelled at its downwind end, beside the line (the upwind end is at the source and its label).
        at = to_map(ends[1:] + np.array([[-u[1], u[0]]]) * 6.0)
        self.log_static("map/wind_field/section/label", rr.Points2D(at, radii=ui(0.1),
                                                                    colors=[C_FIELD_ARROW], labels=["3D section"],
                                                                    draw_order=41.0))  # fmt: skip

    def send_furniture(self, b: Bounds) -> None:
        """The map's furniture (:meth:`SceneMixin.send_furniture`) and, with a wind field, its speed
        colour bar in the bottom-right corner (the concentration one is in the top-right)."""
        super().send_furniture(b)
        v_max = self.wind_vmax_m_s
        if v_max is None:
            return
        n0, n1, e0, e1 = b
        span = min(n1 - n0, e1 - e0)
        pad, h = 0.05 * span, 0.07 * span
        steps = 5
        # Bottom-right (the concentration bar is top-right; the source is often near the top).
        x_bar, y0 = e1 - pad - h, -n0 - pad - h * (steps + 1.2)
        v = np.linspace(v_max, 0.0, steps)  # top = fast
        # Opaque (the field's arrows would show through), in the colours the translucent field takes on the
        # map's background.
        a = WIND_MAP_ALPHA / 255.0
        rgb = a * speed_colormap(v, v_max) + (1.0 - a) * np.asarray(SCENE_BACKGROUND, dtype=float)
        rgba = np.concatenate([np.round(rgb).astype(np.uint8), np.full((steps, 1), 255, dtype=np.uint8)], axis=1)
        bar = rr.Transform3D(translation=[x_bar, y0, 0.0], scale=[h, h, 1.0])
        self.log_static("map/wind_field/colorbar/image", bar)
        self.log_static("map/wind_field/colorbar/image", rr.Image(rgba.reshape(steps, 1, 4), draw_order=39.0))
        self._label("map/wind_field/colorbar/labels", [(x_bar - 0.6 * h, y0 + h * (i + 0.5)) for i in range(steps)],
                    [f"{x:g}" for x in v])  # fmt: skip
        alt = getattr(self, "wind_field_altitude_m", None)
        unit = "m/s" if alt is None else f"m/s at {alt:g} m"
        self._label("map/wind_field/colorbar/unit", (x_bar + 0.5 * h, y0 + h * (steps + 0.6)), unit)


__all__ = ["BUILDINGS_NEAR_M", "UrbanSceneMixin", "nice_ceil", "rectangle"]
