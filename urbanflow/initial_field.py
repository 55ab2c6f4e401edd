"""The initial field on the staggered grid: per-building constants and the face / cell sweeps.

Grid layout (MAC, index k counts cells upward from the ground, h = height above ground):
    cell (i, j, k) centre  north x0 + (i + 0.5) dx, east y0 + (j + 0.5) dy, h = (k + 0.5) dz
    u  (nx + 1, ny, nz)    north component on the x-faces, at north x0 + i dx
    v  (nx, ny + 1, nz)    east component on the y-faces, at east y0 + j dy
    w  (nx, ny, nz + 1)    UP component on the z-faces, at h = k dz (k = 0 is the ground)
The public field (:mod:`.field`) stores the NED down component instead of this w.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .config import UrbanScene
from .geometry import BuildingArrays
from .parameterizations import (
    BP_H,
    BP_HC,
    BP_LC,
    BP_LR,
    BP_REACH,
    BP_SMAX,
    BP_SMIN,
    BP_TMAX,
    BP_TMIN,
    BP_UH,
    N_BP,
    N_OPT,
    OPT_CANYON,
    OPT_COS_ROOF,
    OPT_COS_UPWIND,
    OPT_FAR,
    OPT_LF_COEFF,
    OPT_ROOFTOP,
    OPT_UPWIND,
    OPT_WAKE,
    initial_velocity,
)


def cavity_length(width_m: float, length_m: float, height_m: float) -> float:
    """Fackrell (1984) / Roeckle (1990) lee cavity length L_R (m) behind a block of crosswind
    width W, along-wind length L and height H: ``1.8 W / ((L/H)^0.3 (1 + 0.24 W/H))``, with L/H
    clamped to [0.3, 3] and W/H to <= 10 (the validity range QUIC-URB uses)."""
    l_over_h = min(max(length_m / height_m, 0.3), 3.0)
    w = min(width_m, 10.0 * height_m)
    return 1.8 * w / (l_over_h**0.3 * (1.0 + 0.24 * w / height_m))


def profile_array(scene: UrbanScene) -> np.ndarray:
    """(U_ref, z0, d, 1/ln((z_ref - d)/z0)) of the upstream log profile, kernel order."""
    w = scene.wind
    inv = 1.0 / math.log((w.reference_height_m - w.displacement_m) / w.roughness_length_m)
    return np.array([w.speed_m_s, w.roughness_length_m, w.displacement_m, inv], dtype=np.float64)


def options_array(scene: UrbanScene) -> np.ndarray:
    """The parameterization switches and constants as the kernels' ``opt`` array."""
    o = scene.options
    opt = np.zeros(N_OPT)
    opt[OPT_UPWIND], opt[OPT_ROOFTOP] = float(o.upwind), float(o.rooftop)
    opt[OPT_WAKE], opt[OPT_CANYON] = float(o.wake), float(o.street_canyon)
    opt[OPT_LF_COEFF] = o.upwind_length_coeff
    opt[OPT_COS_UPWIND] = math.cos(math.radians(o.upwind_max_incidence_deg))
    opt[OPT_COS_ROOF] = math.cos(math.radians(o.rooftop_max_incidence_deg))
    opt[OPT_FAR] = o.far_wake_factor
    return opt


def building_params(scene: UrbanScene) -> np.ndarray:
    """Per-building constants (B, N_BP) in wind-aligned coordinates (see ``BP_*``).

    W is the crosswind extent of the footprint, L = area / W (QES-Winds' effective length),
    U_H the upstream speed at roof height, R = B_s^(2/3) B_l^(1/3) the rooftop scale.
    """
    en, ee = scene.wind.direction_ned
    o = scene.options
    bp = np.zeros((len(scene.buildings), N_BP))
    for b, bld in enumerate(scene.buildings):
        fp = bld.footprint()
        s, t = fp @ np.array([en, ee]), fp @ np.array([-ee, en])
        area = 0.5 * abs(float(np.sum(fp[:, 0] * np.roll(fp[:, 1], -1) - np.roll(fp[:, 0], -1) * fp[:, 1])))
        H = bld.height_m
        W = float(t.max() - t.min())
        L = area / W
        lr = cavity_length(W, L, H)
        r = min(W, H) ** (2.0 / 3.0) * max(W, H) ** (1.0 / 3.0)
        edges = np.linalg.norm(np.roll(fp, -1, axis=0) - fp, axis=1)
        reach_up = o.upwind_length_coeff * float(edges.max())
        bp[b, BP_H], bp[b, BP_UH] = H, float(scene.wind.speed_at(H))
        bp[b, BP_TMIN], bp[b, BP_TMAX] = float(t.min()), float(t.max())
        bp[b, BP_LR], bp[b, BP_LC], bp[b, BP_HC] = lr, 0.9 * r, 0.22 * r
        bp[b, BP_SMIN], bp[b, BP_SMAX] = float(s.min()), float(s.max())
        bp[b, BP_REACH] = max(reach_up, o.far_wake_factor * lr, lr) + 1.0
    return bp


@njit(cache=True)
def initial_faces(
    x0: float, y0: float, dx: float, dy: float, dz: float, nx: int, ny: int, nz: int,
    en: float, ee: float, prof: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bp: np.ndarray, opt: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, w_up) of the initial field on the faces (layout in the module docstring), m/s."""
    u = np.empty((nx + 1, ny, nz))
    v = np.empty((nx, ny + 1, nz))
    w = np.zeros((nx, ny, nz + 1))
    for i in range(nx + 1):
        for j in range(ny + 1):
            for k in range(nz + 1):
                xc, yc, hc = x0 + (i + 0.5) * dx, y0 + (j + 0.5) * dy, (k + 0.5) * dz
                xf, yf, hf = x0 + i * dx, y0 + j * dy, k * dz  # face positions
                if j < ny and k < nz:
                    u[i, j, k] = initial_velocity(xf, yc, hc, en, ee, prof, verts, offsets, heights, bp, opt)[0]
                if i < nx and k < nz:
                    v[i, j, k] = initial_velocity(xc, yf, hc, en, ee, prof, verts, offsets, heights, bp, opt)[1]
                if i < nx and j < ny and k > 0:
                    w[i, j, k] = initial_velocity(xc, yc, hf, en, ee, prof, verts, offsets, heights, bp, opt)[2]
    return u, v, w


@njit(cache=True)
def zone_map(
    x0: float, y0: float, dx: float, dy: float, dz: float, cell_building: np.ndarray,
    en: float, ee: float, prof: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bp: np.ndarray, opt: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(zone int8, U_zone m/s) at the cell centres; zone -1 in building cells."""
    nx, ny, nz = cell_building.shape
    zone = np.empty((nx, ny, nz), dtype=np.int8)
    u_zone = np.zeros((nx, ny, nz))
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if cell_building[i, j, k] >= 0:
                    zone[i, j, k] = -1
                    continue
                r = initial_velocity(
                    x0 + (i + 0.5) * dx, y0 + (j + 0.5) * dy, (k + 0.5) * dz, en, ee, prof,
                    verts, offsets, heights, bp, opt,
                )
                zone[i, j, k] = r[3]
                u_zone[i, j, k] = r[4]
    return zone, u_zone


def initial_field(scene: UrbanScene, geom: BuildingArrays) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, w_up) initial field of ``scene`` on its grid (solid faces not yet zeroed)."""
    g = scene.grid
    nx, ny, nz = g.shape
    en, ee = scene.wind.direction_ned
    return initial_faces(
        g.x_min_m, g.y_min_m, g.spacing_m, g.spacing_m, g.dz, nx, ny, nz, en, ee,
        profile_array(scene), *geom.args()[:3], building_params(scene), options_array(scene),
    )
