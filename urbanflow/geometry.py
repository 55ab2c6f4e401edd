"""Building geometry as flat arrays and its numba kernels: inside tests, puff reflection, voxels.

Buildings are vertical prisms: a simple polygon footprint (counter-clockwise in the NED (x, y)
plane, so the outward normal of edge a->b is ``(b_y - a_y, -(b_x - a_x)) / |b - a|``) extruded
from the ground (height 0) to the roof height H. Points are NED (x north, y east, z down), so a
point's height is ``h = -z``; a point is inside building b when ``0 <= h < H_b`` and its (x, y)
lies inside the footprint (even-odd rule). The exact geometry (not the voxels of the wind grid)
decides collisions and reflections, so a vehicle crashes where the real wall is.

Array layout (:class:`BuildingArrays`, what the kernels take):
    verts    float64 (V, 2)  footprint vertices of all buildings, (north, east) m
    offsets  int64   (B+1,)  building b owns verts[offsets[b]:offsets[b+1]]
    heights  float64 (B,)    roof heights (m above ground)
    bbox     float64 (B, 4)  (x_min, x_max, y_min, y_max) of each footprint (m)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from .config import Building

# A reflected point is put this far (m) outside a face when it cannot be mirrored cleanly.
PUSH_OUT_M = 1e-3
_MAX_REFLECTIONS = 4


@dataclass(frozen=True, eq=False)
class BuildingArrays:
    """Flat arrays of the building prisms (see the module docstring for the layout)."""

    verts: np.ndarray
    offsets: np.ndarray
    heights: np.ndarray
    bbox: np.ndarray

    @classmethod
    def from_buildings(cls, buildings: Sequence[Building]) -> BuildingArrays:
        fps = [b.footprint() for b in buildings]
        offsets = np.zeros(len(fps) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([len(f) for f in fps])
        verts = np.ascontiguousarray(np.concatenate(fps) if fps else np.zeros((0, 2)), dtype=np.float64)
        bbox = np.array(
            [[f[:, 0].min(), f[:, 0].max(), f[:, 1].min(), f[:, 1].max()] for f in fps], dtype=np.float64
        ).reshape(-1, 4)
        heights = np.array([b.height_m for b in buildings], dtype=np.float64)
        return cls(verts, offsets, heights, bbox)

    def args(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(verts, offsets, heights, bbox) in kernel order."""
        return (self.verts, self.offsets, self.heights, self.bbox)


@njit(cache=True, inline="always")
def in_footprint(x: float, y: float, b: int, verts: np.ndarray, offsets: np.ndarray, bbox: np.ndarray) -> bool:
    """(x, y) inside the footprint of building b (even-odd ray casting along +y)."""
    if x < bbox[b, 0] or x > bbox[b, 1] or y < bbox[b, 2] or y > bbox[b, 3]:
        return False
    inside = False
    i0 = offsets[b]
    n = offsets[b + 1] - i0
    for k in range(n):
        ax, ay = verts[i0 + k, 0], verts[i0 + k, 1]
        bx, by = verts[i0 + (k + 1) % n, 0], verts[i0 + (k + 1) % n, 1]
        if (ax > x) != (bx > x):
            y_cross = ay + (x - ax) * (by - ay) / (bx - ax)
            if y < y_cross:
                inside = not inside
    return inside


@njit(cache=True, inline="always")
def building_at(
    x: float, y: float, h: float, verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray
) -> int:
    """Index of the building containing the point at height h (m above ground), else -1."""
    if h < 0.0:
        return -1
    for b in range(heights.shape[0]):
        if h < heights[b] and in_footprint(x, y, b, verts, offsets, bbox):
            return b
    return -1


@njit(cache=True)
def inside_many(
    points_ned: np.ndarray, verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray
) -> np.ndarray:
    """bool (N,): NED points (N, 3) m inside any building (a vehicle there has crashed)."""
    n = points_ned.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for k in range(n):
        out[k] = building_at(points_ned[k, 0], points_ned[k, 1], -points_ned[k, 2], verts, offsets, heights, bbox) >= 0
    return out


@njit(cache=True)
def _entry_face(
    qx: float, qy: float, qh: float, px: float, py: float, ph: float, b: int,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray,
) -> tuple[float, int]:
    """(t, face) of the first crossing of segment q->p into building b; face -1 = roof, -2 = none.

    Wall faces are numbered by their first vertex index in ``verts``.
    """
    best_t = 2.0
    face = -2
    hb = heights[b]
    if qh >= hb > ph:
        best_t = (qh - hb) / (qh - ph)
        face = -1
    i0 = offsets[b]
    n = offsets[b + 1] - i0
    rx, ry = px - qx, py - qy
    for k in range(n):
        ax, ay = verts[i0 + k, 0], verts[i0 + k, 1]
        bx, by = verts[i0 + (k + 1) % n, 0], verts[i0 + (k + 1) % n, 1]
        sx, sy = bx - ax, by - ay
        den = rx * sy - ry * sx
        if abs(den) < 1e-15:
            continue
        t = ((ax - qx) * sy - (ay - qy) * sx) / den
        u = ((ax - qx) * ry - (ay - qy) * rx) / den
        # Entering through this wall: the segment moves against the outward normal (sy, -sx).
        if 0.0 <= t < best_t and 0.0 <= u <= 1.0 and den < 0.0 and qh + t * (ph - qh) < hb:
            best_t = t
            face = i0 + k
    return best_t, face


@njit(cache=True)
def _push_out(
    px: float, py: float, ph: float, b: int, verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray
) -> tuple[float, float, float]:
    """Move a point inside building b just outside its nearest face (wall or roof)."""
    best = heights[b] - ph
    nx_, ny_, roof = 0.0, 0.0, True
    i0 = offsets[b]
    n = offsets[b + 1] - i0
    for k in range(n):
        ax, ay = verts[i0 + k, 0], verts[i0 + k, 1]
        bx, by = verts[i0 + (k + 1) % n, 0], verts[i0 + (k + 1) % n, 1]
        ln = math.hypot(bx - ax, by - ay)
        ox, oy = (by - ay) / ln, -(bx - ax) / ln
        dist = -((px - ax) * ox + (py - ay) * oy)  # > 0 inside, distance to the wall's plane
        if 0.0 <= dist < best:
            best, nx_, ny_, roof = dist, ox, oy, False
    if roof:
        return px, py, heights[b] + PUSH_OUT_M
    return px + (best + PUSH_OUT_M) * nx_, py + (best + PUSH_OUT_M) * ny_, ph


@njit(cache=True)
def edge_normal(e: int, b: int, verts: np.ndarray, offsets: np.ndarray) -> tuple[float, float]:
    """Outward unit normal (north, east) of edge e (first vertex index) of building b."""
    i0 = offsets[b]
    n = offsets[b + 1] - i0
    k = e - i0
    ax, ay = verts[e, 0], verts[e, 1]
    bx, by = verts[i0 + (k + 1) % n, 0], verts[i0 + (k + 1) % n, 1]
    ln = math.hypot(bx - ax, by - ay)
    return (by - ay) / ln, -(bx - ax) / ln


@njit(cache=True)
def reflect_point(
    qx: float, qy: float, qh: float, px: float, py: float, ph: float,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> tuple[float, float, float]:
    """Point p (height ph) mirrored out of any building it entered on its way from q.

    The part of the step that went through a wall (or the roof) is mirrored across that face's
    plane, as a specular reflection; repeated for corners (up to 4 times). A point that cannot be
    placed outside that way (q itself inside, or corner cases) is pushed just outside the
    nearest face. Heights are m above ground.
    """
    for _ in range(_MAX_REFLECTIONS):
        b = building_at(px, py, ph, verts, offsets, heights, bbox)
        if b < 0:
            return px, py, ph
        t, face = _entry_face(qx, qy, qh, px, py, ph, b, verts, offsets, heights)
        if face == -2:
            return _push_out(px, py, ph, b, verts, offsets, heights)
        cx, cy, ch = qx + t * (px - qx), qy + t * (py - qy), qh + t * (ph - qh)
        if face == -1:
            ph = 2.0 * heights[b] - ph
            ch += PUSH_OUT_M
        else:
            ox, oy = edge_normal(face, b, verts, offsets)
            ax, ay = verts[face, 0], verts[face, 1]
            d = (px - ax) * ox + (py - ay) * oy  # < 0: depth behind the wall
            px -= 2.0 * d * ox
            py -= 2.0 * d * oy
            cx += PUSH_OUT_M * ox
            cy += PUSH_OUT_M * oy
        qx, qy, qh = cx, cy, ch  # the rest of the step starts at the face
    b = building_at(px, py, ph, verts, offsets, heights, bbox)
    if b >= 0:
        return _push_out(px, py, ph, b, verts, offsets, heights)
    return px, py, ph


@njit(cache=True)
def reflect_many(
    points_ned: np.ndarray, prev_ned: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> tuple[np.ndarray, int]:
    """(new points (N, 3) NED m, number moved): points that entered a building since ``prev_ned``
    reflected out of it (see :func:`reflect_point`); points outside every building are unchanged."""
    n = points_ned.shape[0]
    out = points_ned.copy()
    moved = 0
    for k in range(n):
        px, py, ph = points_ned[k, 0], points_ned[k, 1], -points_ned[k, 2]
        if building_at(px, py, ph, verts, offsets, heights, bbox) < 0:
            continue
        rx, ry, rh = reflect_point(
            prev_ned[k, 0], prev_ned[k, 1], -prev_ned[k, 2], px, py, ph, verts, offsets, heights, bbox
        )
        out[k, 0], out[k, 1], out[k, 2] = rx, ry, -rh
        moved += 1
    return out, moved


@njit(cache=True)
def voxelize(
    x0: float, y0: float, dx: float, dy: float, dz: float, nx: int, ny: int, nz: int,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bbox: np.ndarray,
) -> np.ndarray:
    """int32 (nx, ny, nz): index of the building containing each cell centre, -1 for air.

    Cell (i, j, k) has its centre at north x0 + (i + 0.5) dx, east y0 + (j + 0.5) dy, height
    (k + 0.5) dz. Later buildings win where footprints overlap.
    """
    out = np.full((nx, ny, nz), -1, dtype=np.int32)
    for b in range(heights.shape[0]):
        i_lo = max(int((bbox[b, 0] - x0) / dx) - 1, 0)
        i_hi = min(int((bbox[b, 1] - x0) / dx) + 2, nx)
        j_lo = max(int((bbox[b, 2] - y0) / dy) - 1, 0)
        j_hi = min(int((bbox[b, 3] - y0) / dy) + 2, ny)
        k_hi = min(int(math.ceil(heights[b] / dz - 0.5)), nz)  # centres with (k + 0.5) dz < H
        for i in range(i_lo, i_hi):
            for j in range(j_lo, j_hi):
                if in_footprint(x0 + (i + 0.5) * dx, y0 + (j + 0.5) * dy, b, verts, offsets, bbox):
                    for k in range(k_hi):
                        out[i, j, k] = b
    return out
