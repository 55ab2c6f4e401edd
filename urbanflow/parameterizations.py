"""Empirical building parameterizations of QUIC-URB: the initial (first-guess) wind field.

The initial field is a pure function of position, :func:`initial_velocity`, evaluated at every
face of the staggered grid (and at cell centres for the zone map). Start: the upstream log
profile ``U(h) e`` (e = unit direction the air moves toward). Then, per building, in wind-aligned
coordinates s (along the wind) and t (across), with W the crosswind width of the footprint, H the
roof height, L = area / W the effective along-wind length and U_H = U(H):

* Upwind (frontal) zone, the modified vortex parameterization (MVP) of Bagal et al. (2004) as in
  QUIC-URB / QES-Winds: for each windward face of width W_f met at incidence theta,
  ``L_F = 1.5 W_f cos(theta) / (1 + 0.8 W_f / H)`` (Roeckle 1990 uses 2.0), an ellipsoid
  ``d <= L_F sqrt((1 - (q / (W_f/2))^2) (1 - (h / 0.6 H)^2))`` in front of the face (d from the
  face, q along it). Outer 60 % of the ellipsoid: velocity x 0.4. Inner 40 %: the face-normal
  component is the vortex ``-U_H cos(theta) 0.6 sin(pi d / 0.4 L_F) (0.6 cos(2 pi h / H) - 0.05)``
  (reversed near the ground), the tangential one x 0.4, and ``w = -U_H cos(theta) (0.1 cos(pi d /
  0.4 L_F) - 0.05)`` (up positive).
* Lee-side cavity and far wake (Roeckle 1990; Kaplan & Dinar 1996; QUIC-URB, Pardyjak & Brown
  2003; Singh et al. 2008): cavity length from Fackrell (1984),
  ``L_R = 1.8 W / ((L/H)^0.3 (1 + 0.24 W/H))`` with L/H clamped to [0.3, 3] and W/H to <= 10;
  at distance x behind the back face, ``d_N = L_R sqrt((1 - (t'/(W/2))^2)(1 - (h/H)^2))``;
  cavity ``x <= d_N``: ``u = -U_H (1 - x/d_N)^2`` along the wind, w = 0; far wake
  ``d_N < x <= 3 d_N``: velocity x ``(1 - (d_N/x)^1.5)``, w = 0. The back face is the footprint's
  downwind edge at that t (QUIC-URB's offset for rotated buildings, generalized to polygons).
  A wake stops at the next building downstream.
* Street canyon (Singh et al. 2008, after Roeckle 1990 and Kaplan & Dinar 1996): when the next
  building downstream at (t, h) is closer than L_R, the gap S is a canyon; with x from the
  upwind wall, ``u_cross = -U_c (x / 0.5S)((S - x) / 0.5S)``,
  ``w = -U_c |0.5 (1 - x/0.5S)| (1 - (S - x)/0.5S)`` (up positive), U_c the component of U_H
  across the downwind face, and the along-canyon component of the log profile kept (as
  QES-Winds).
* Rooftop recirculation (Bagal et al. 2004; Pol et al. 2006, as in QES-Winds): for a leading face
  within 30 deg of the wind and no taller building sheltering it, ``R = B_s^(2/3) B_l^(1/3)``
  (B_s, B_l the smaller and larger of H and W), ``L_c = 0.9 R``, ``H_c = 0.22 R``; above the roof
  for ``x_r < L_c`` from the leading edge and ``z_r < H_c sqrt(1 - ((L_c/2 - x_r)/(L_c/2))^2)``:
  ``u = -U(h) (shell - z_r) / H_c`` (reversed), w = 0.

Priorities where zones overlap (QUIC-URB's order): canyon > cavity > rooftop > upwind; far-wake
factors of all buildings multiply the rest. Formulas were taken from the QES-Winds documentation
(Bozorgmehr et al. 2021, "QES-Winds: Fast-response Wind Solver", UtahEFD/QES-Public docs) and the
cited papers; this is an independent implementation. Zone codes: see ``ZONE_*``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .geometry import edge_normal

ZONE_SOLID = -1
ZONE_FREE = 0
ZONE_UPWIND = 1
ZONE_UPWIND_VORTEX = 2
ZONE_ROOFTOP = 3
ZONE_CAVITY = 4
ZONE_WAKE = 5
ZONE_CANYON = 6
ZONE_NAMES = {
    -1: "solid", 0: "free", 1: "upwind", 2: "upwind vortex", 3: "rooftop", 4: "cavity", 5: "wake", 6: "canyon"
}

# Columns of the per-building parameter array ``bp`` (B, N_BP).
BP_H, BP_UH, BP_TMIN, BP_TMAX, BP_LR, BP_LC, BP_HC, BP_SMIN, BP_SMAX, BP_REACH = range(10)
N_BP = 10
# Entries of the options array ``opt``.
OPT_UPWIND, OPT_ROOFTOP, OPT_WAKE, OPT_CANYON, OPT_LF_COEFF, OPT_COS_UPWIND, OPT_COS_ROOF, OPT_FAR = range(8)
N_OPT = 8


@njit(cache=True)
def log_speed(h: float, u_ref: float, z0: float, disp: float, inv_log_ref: float) -> float:
    """Upstream log-law speed (m/s) at height h (m); 0 at and below disp + z0."""
    return u_ref * math.log(max((h - disp) / z0, 1.0)) * inv_log_ref


@njit(cache=True)
def front_back(
    b: int, t: float, en: float, ee: float, verts: np.ndarray, offsets: np.ndarray
) -> tuple[bool, float, float, int, int]:
    """(found, s_front, s_back, edge_front, edge_back) where the line t = const crosses building b.

    s = p . e, t = p . (-e_e, e_n); edges are named by their first vertex's index in ``verts``.
    """
    i0 = offsets[b]
    n = offsets[b + 1] - i0
    found = False
    sf, sb, ef, eb = 1e300, -1e300, -1, -1
    for k in range(n):
        ax, ay = verts[i0 + k, 0], verts[i0 + k, 1]
        bx, by = verts[i0 + (k + 1) % n, 0], verts[i0 + (k + 1) % n, 1]
        ta, tb = -ax * ee + ay * en, -bx * ee + by * en
        if ta == tb or (ta - t) * (tb - t) > 0.0:
            continue
        sa, sb_ = ax * en + ay * ee, bx * en + by * ee
        s = sa + (t - ta) / (tb - ta) * (sb_ - sa)
        found = True
        if s < sf:
            sf, ef = s, i0 + k
        if s > sb:
            sb, eb = s, i0 + k
    return found, sf, sb, ef, eb


@njit(cache=True)
def downstream_hit(
    b: int, t: float, s_back: float, h: float, en: float, ee: float,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bp: np.ndarray,
) -> tuple[float, int, int]:
    """(distance S, building, front edge) of the first other building met going downwind from
    building b's back face at (t, h); S = 1e300 when none, 0 when the back face is inside one."""
    best, bb, be = 1e300, -1, -1
    for b2 in range(heights.shape[0]):
        if b2 == b or h >= heights[b2] or t <= bp[b2, BP_TMIN] or t >= bp[b2, BP_TMAX]:
            continue
        found, sf2, sb2, ef2, _ = front_back(b2, t, en, ee, verts, offsets)
        if not found or sb2 <= s_back:
            continue
        dist = max(sf2 - s_back, 0.0)
        if dist < best:
            best, bb, be = dist, b2, ef2
    return best, bb, be


@njit(cache=True)
def _sheltered(b: int, t: float, s_front: float, en: float, ee: float,
               verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bp: np.ndarray) -> bool:
    """True if a building at least as tall as b stands upwind within its cavity length of b's
    leading edge at t (no rooftop vortex then, as QES-Winds)."""
    for b0 in range(heights.shape[0]):
        if b0 == b or heights[b0] < heights[b] or t <= bp[b0, BP_TMIN] or t >= bp[b0, BP_TMAX]:
            continue
        found, _, sb0, _, _ = front_back(b0, t, en, ee, verts, offsets)
        if found and sb0 <= s_front + 1e-9 and s_front - sb0 <= bp[b0, BP_LR]:
            return True
    return False


@njit(cache=True)
def _upwind(
    x: float, y: float, h: float, b: int, en: float, ee: float, u_h_base: float,
    verts: np.ndarray, offsets: np.ndarray, bp: np.ndarray, opt: np.ndarray,
) -> tuple[float, float, float, float, int]:
    """(ratio d / extent, vn, ve, vup, zone) of building b's frontal zone at the point; ratio > 1
    when outside every windward face's ellipsoid. ``u_h_base`` is U(h) of the log profile."""
    H, uh = bp[b, BP_H], bp[b, BP_UH]
    best, vn, ve, vu, zone = 2.0, 0.0, 0.0, 0.0, ZONE_FREE
    if h >= 0.6 * H:
        return best, vn, ve, vu, zone
    i0 = offsets[b]
    n = offsets[b + 1] - i0
    for k in range(n):
        ox, oy = edge_normal(i0 + k, b, verts, offsets)
        c = -(ox * en + oy * ee)  # cos(incidence): the wind blows into the face
        if c < opt[OPT_COS_UPWIND]:
            continue
        ax, ay = verts[i0 + k, 0], verts[i0 + k, 1]
        bx, by = verts[i0 + (k + 1) % n, 0], verts[i0 + (k + 1) % n, 1]
        wf = math.hypot(bx - ax, by - ay)
        d = (x - 0.5 * (ax + bx)) * ox + (y - 0.5 * (ay + by)) * oy
        q = ((x - 0.5 * (ax + bx)) * (bx - ax) + (y - 0.5 * (ay + by)) * (by - ay)) / wf
        if d < 0.0 or abs(q) >= 0.5 * wf:
            continue
        lf = opt[OPT_LF_COEFF] * wf * c / (1.0 + 0.8 * wf / H)
        xe = lf * math.sqrt((1.0 - (q / (0.5 * wf)) ** 2) * (1.0 - (h / (0.6 * H)) ** 2))
        if xe <= 0.0 or d > xe or d / xe >= best:
            continue
        best = d / xe
        bn, bt_n, bt_e = u_h_base * c, u_h_base * (en + c * ox), u_h_base * (ee + c * oy)  # normal, tangential
        if d <= 0.4 * xe:
            un = -uh * c * 0.6 * math.sin(math.pi * d / (0.4 * lf)) * (0.6 * math.cos(2.0 * math.pi * h / H) - 0.05)
            vn, ve = -un * ox + 0.4 * bt_n, -un * oy + 0.4 * bt_e  # into the face is -outward normal
            vu = -uh * c * (0.1 * math.cos(math.pi * d / (0.4 * lf)) - 0.05)
            zone = ZONE_UPWIND_VORTEX
        else:
            vn, ve, vu, zone = -0.4 * bn * ox + 0.4 * bt_n, -0.4 * bn * oy + 0.4 * bt_e, 0.0, ZONE_UPWIND
    return best, vn, ve, vu, zone


@njit(cache=True)
def _lee(
    s: float, t: float, h: float, b: int, en: float, ee: float,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bp: np.ndarray, opt: np.ndarray,
) -> tuple[int, float, float, float, int, int]:
    """Building b's lee at the point: (kind, dl, d_N or S, wake factor, b2, edge2).

    kind 0: none, 4: cavity, 5: far wake, 6: canyon (then the third value is the gap S and
    b2 / edge2 the downwind building and its front edge)."""
    H = bp[b, BP_H]
    if h >= H or t <= bp[b, BP_TMIN] or t >= bp[b, BP_TMAX]:
        return 0, 0.0, 0.0, 1.0, -1, -1
    found, _, sb, _, _ = front_back(b, t, en, ee, verts, offsets)
    if not found or s <= sb:
        return 0, 0.0, 0.0, 1.0, -1, -1
    dl = s - sb
    half_w = 0.5 * (bp[b, BP_TMAX] - bp[b, BP_TMIN])
    t_rel = (t - 0.5 * (bp[b, BP_TMAX] + bp[b, BP_TMIN])) / half_w
    lr = bp[b, BP_LR]
    dn = lr * math.sqrt(max((1.0 - t_rel * t_rel) * (1.0 - (h / H) ** 2), 0.0))
    far = opt[OPT_FAR] * dn
    if dl > max(far, lr):
        return 0, 0.0, 0.0, 1.0, -1, -1
    gap, b2, e2 = downstream_hit(b, t, sb, h, en, ee, verts, offsets, heights, bp)
    if dl >= gap:
        return 0, 0.0, 0.0, 1.0, -1, -1  # behind another building: this wake has ended
    if opt[OPT_CANYON] > 0.0 and gap <= lr:
        return ZONE_CANYON, dl, gap, 1.0, b2, e2
    if opt[OPT_WAKE] > 0.0 and dl <= dn:
        return ZONE_CAVITY, dl, dn, 1.0, -1, -1
    if opt[OPT_WAKE] > 0.0 and dl <= far:
        return ZONE_WAKE, dl, dn, 1.0 - (dn / dl) ** 1.5, -1, -1
    return 0, 0.0, 0.0, 1.0, -1, -1


@njit(cache=True)
def _canyon_velocity(
    dl: float, gap: float, b: int, b2: int, e2: int, h_speed: float, en: float, ee: float,
    verts: np.ndarray, offsets: np.ndarray, bp: np.ndarray,
) -> tuple[float, float, float]:
    """(vn, ve, vup) of the canyon vortex between building b and the downwind b2 (front edge e2)."""
    ox, oy = edge_normal(e2, b2, verts, offsets)
    cx, cy = -ox, -oy  # across the canyon, into the downwind face
    cos_t = max(en * cx + ee * cy, 0.0)
    u_c = bp[b, BP_UH] * cos_t
    r = dl / gap
    cross = -u_c * 4.0 * r * (1.0 - r)
    w_up = -u_c * abs(0.5 * (1.0 - 2.0 * r)) * (2.0 * r - 1.0)
    along_n, along_e = h_speed * (en - cos_t * cx), h_speed * (ee - cos_t * cy)
    return along_n + cross * cx, along_e + cross * cy, w_up


@njit(cache=True)
def _rooftop(
    s: float, t: float, h: float, b: int, en: float, ee: float,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bp: np.ndarray, opt: np.ndarray,
) -> float:
    """Reversal factor (shell - z_r) / H_c > 0 inside building b's rooftop vortex, else -1."""
    H, hc, lc = bp[b, BP_H], bp[b, BP_HC], bp[b, BP_LC]
    if h < H or h >= H + hc or t <= bp[b, BP_TMIN] or t >= bp[b, BP_TMAX]:
        return -1.0
    found, sf, sb, ef, _ = front_back(b, t, en, ee, verts, offsets)
    if not found or s < sf or s > sb or s - sf >= lc:
        return -1.0
    ox, oy = edge_normal(ef, b, verts, offsets)
    if -(ox * en + oy * ee) < opt[OPT_COS_ROOF]:
        return -1.0
    xr = (s - sf) / (0.5 * lc) - 1.0
    shell = hc * math.sqrt(max(1.0 - xr * xr, 0.0))
    zr = h - H
    if zr >= shell or _sheltered(b, t, sf, en, ee, verts, offsets, heights, bp):
        return -1.0
    return (shell - zr) / hc


@njit(cache=True)
def initial_velocity(
    x: float, y: float, h: float, en: float, ee: float, prof: np.ndarray,
    verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray, bp: np.ndarray, opt: np.ndarray,
) -> tuple[float, float, float, int, float]:
    """(vn, ve, vup, zone, U_zone) of the initial field at (x, y) NED m, height h (m).

    ``prof`` = (U_ref, z0, d, 1/ln((z_ref - d)/z0)). U_zone is the building-height speed of the
    cavity / canyon / rooftop zone (the turbulence floor), tapered to 0 across a far wake.
    """
    s, t = x * en + y * ee, -x * ee + y * en
    uh = log_speed(h, prof[0], prof[1], prof[2], prof[3])
    vn, ve, vu, zone, u_zone = uh * en, uh * ee, 0.0, ZONE_FREE, 0.0
    best_can, best_cav, best_up, roof_f, wake_f = 1e300, 1e300, 2.0, -1.0, 1.0
    can_b = cav_b = roof_b = -1
    can = (0.0, 0.0, 0.0)
    cav_dn = 1.0
    for b in range(heights.shape[0]):
        if s < bp[b, BP_SMIN] - bp[b, BP_REACH] or s > bp[b, BP_SMAX] + bp[b, BP_REACH]:
            continue
        if t < bp[b, BP_TMIN] - bp[b, BP_REACH] or t > bp[b, BP_TMAX] + bp[b, BP_REACH]:
            continue
        kind, dl, size, f, b2, e2 = _lee(s, t, h, b, en, ee, verts, offsets, heights, bp, opt)
        if kind == ZONE_CANYON and dl < best_can:
            best_can, can_b = dl, b
            can = _canyon_velocity(dl, size, b, b2, e2, uh, en, ee, verts, offsets, bp)
        elif kind == ZONE_CAVITY and dl < best_cav:
            best_cav, cav_b = dl, b
            cav_dn = size
        elif kind == ZONE_WAKE:
            wake_f *= f
            u_zone = max(u_zone, bp[b, BP_UH] * (opt[OPT_FAR] * size - dl) / ((opt[OPT_FAR] - 1.0) * size))
        if opt[OPT_ROOFTOP] > 0.0 and roof_b < 0:
            roof_f = _rooftop(s, t, h, b, en, ee, verts, offsets, heights, bp, opt)
            if roof_f > 0.0:
                roof_b = b
        if opt[OPT_UPWIND] > 0.0:
            r, un_, ue_, uu_, z_ = _upwind(x, y, h, b, en, ee, uh, verts, offsets, bp, opt)
            if r < best_up:
                best_up, vn, ve, vu, zone = r, un_, ue_, uu_, z_
    if can_b >= 0:
        return can[0], can[1], can[2], ZONE_CANYON, bp[can_b, BP_UH]
    if cav_b >= 0:
        rev = -bp[cav_b, BP_UH] * (1.0 - best_cav / cav_dn) ** 2
        return rev * en, rev * ee, 0.0, ZONE_CAVITY, bp[cav_b, BP_UH]
    if roof_b >= 0:
        return -uh * roof_f * en, -uh * roof_f * ee, 0.0, ZONE_ROOFTOP, bp[roof_b, BP_UH]
    if wake_f < 1.0:
        vn, ve, vu = vn * wake_f, ve * wake_f, 0.0
        if zone == ZONE_FREE:
            zone = ZONE_WAKE
    return vn, ve, vu, zone, u_zone
