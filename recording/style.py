"""What a windseek recording looks like: the timeline, colours, colour maps and plain-words names.

One place for every colour so the map, the 3D view, the time series and the summary's key agree.
Colours are RGB(A) tuples of 0-255 integers, chosen to read on both the viewer's dark and light
themes (the map and 3D views draw on their own light background, :data:`SCENE_BACKGROUND`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: The one timeline every entity is logged on: the vehicle's clock in seconds (a duration).
#: In simulation it is the simulation time; in a reviewed log the log's clock from its start; the
#: mission's own lines and results use the same clock (durations are counted from arming).
TIMELINE = "vehicle_time"
AXES = ("north", "east", "down")
TEXT_LEVELS = ("TRACE", "DEBUG", "INFO", "WARN", "ERROR", "CRITICAL")

Rgb = tuple[int, int, int]
#: A vector argument: a sequence of floats or a numpy array (SI units, NED).
VecLike = Sequence[float] | np.ndarray

C_TRUTH: Rgb = (31, 119, 180)  # blue
C_EST: Rgb = (255, 127, 14)  # orange
#: Translucent orange: the +-2 sigma band, drawn as a line crossing it several times per pixel (the
#: crossings overlap, so it looks more opaque than its alpha; the estimate's line must show through).
C_BAND: tuple[int, int, int, int] = (255, 127, 14, 60)
C_RAW: Rgb = (150, 150, 150)  # grey
C_THRESH: Rgb = (214, 39, 40)  # red: the detection threshold
C_AUTOPILOT: Rgb = (44, 160, 44)  # green: an autopilot's own wind estimate (reviews)
#: Three components of one quantity (velocity north / east / down, roll / pitch / yaw).
C_AXES3: tuple[Rgb, Rgb, Rgb] = ((31, 119, 180), (44, 160, 44), (214, 39, 40))
C_GPS: Rgb = (140, 86, 75)  # brown: GPS fixes (altitude, track), apart from the position estimate
C_ROTORS: tuple[Rgb, ...] = ((228, 26, 28), (55, 126, 184), (77, 175, 74), (152, 78, 163))
C_SOURCE: Rgb = (200, 0, 0)  # the true source
C_DECLARED: Rgb = (0, 140, 60)  # the declared source and its credible region
C_VEHICLE: Rgb = (20, 20, 20)
C_TRAIL_3D: Rgb = (30, 90, 170)  # the path in 3D (the map colours it by strategy state)
C_FENCE: Rgb = (200, 60, 60)
C_FURNITURE: Rgb = (40, 40, 40)  # north arrow, scale bar, labels
#: Wind arrows on the map: darker than the path's colours (they start at the vehicle, over its path).
C_MAP_TRUTH: Rgb = (0, 50, 150)
C_MAP_EST: Rgb = (210, 80, 0)
C_POSTERIOR: Rgb = (94, 60, 153)  # purple: a strategy's source posterior
#: Phase markers on the time series: take-off / search start / landing, verification sweeps, declaration.
C_MARK_PHASE: Rgb = (110, 110, 110)
C_MARK_VERIFY: Rgb = (148, 103, 189)
C_MARK_DECLARED: Rgb = (0, 140, 60)
#: Buildings (urban scenarios): a translucent warm grey fill (the path, plume and field behind stay
#: visible), a dark outline and dark labels.
C_BUILDING: tuple[int, int, int, int] = (150, 140, 125, 110)
C_BUILDING_MAP: tuple[int, int, int, int] = (120, 112, 100, 190)
C_BUILDING_EDGE: Rgb = (70, 62, 52)
#: Arrows of the mean wind field (map and vertical section): dark slate, under the path's colours.
C_FIELD_ARROW: Rgb = (55, 65, 85)
#: Background of the map and 3D views (fixed, so the colour maps read the same in both themes).
SCENE_BACKGROUND: Rgb = (246, 245, 240)

#: Colours of the path by strategy state (and by flight phase before the search). Blues, greens,
#: purples and greys only: the plume's colour map is yellow-orange-red.
STATE_COLORS: dict[str, Rgb] = {
    "ground": (150, 150, 150), "take-off": (150, 150, 150), "hover": (120, 120, 120),
    "landing": (120, 120, 120), "landed": (150, 150, 150),
    "acquire": (31, 119, 180), "search": (31, 119, 180), "wait-wind": (120, 120, 120),
    "surge": (0, 150, 80), "upwind": (0, 150, 80),
    "cast": (148, 103, 189), "lost": (148, 103, 189), "zig": (0, 150, 80), "upwind-lost": (148, 103, 189),
    "verify": (23, 160, 190), "descend": (20, 20, 20), "done": (20, 20, 20),
}  # fmt: skip
_FALLBACK: tuple[Rgb, ...] = ((57, 59, 121), (82, 84, 163), (107, 110, 207), (99, 121, 57), (140, 162, 82))

#: What a strategy state means, for the events log (states of mission/strategies/*).
STATE_TEXT: dict[str, str] = {
    "acquire": "looking for the plume (crosswind sweeps)",
    "surge": "in the plume: flying upwind",
    "cast": "plume lost: casting crosswind to find it again",
    "verify": "verification sweep upwind of the candidate source",
    "descend": "source declared: descending over it",
    "done": "search done",
    "upwind": "flying upwind on the filtered wind direction",
    "upwind-lost": "flying upwind, plume lost",
    "zig": "zig-zag upwind across the plume",
    "lost": "plume lost: widening sweeps",
    "wait-wind": "waiting for a usable wind direction",
    "search": "searching (information-seeking moves)",
}

#: Lanes of the mission phase in the state timeline, in flight order, with their colours.
PHASES: tuple[str, ...] = ("on ground", "armed", "take-off", "hover", "search", "verify", "descend", "landing",
                           "landed")  # fmt: skip
PHASE_COLORS: tuple[Rgb, ...] = ((170, 170, 170), (200, 200, 120), (120, 170, 220), (150, 150, 200), (31, 119, 180),
                                 (23, 160, 190), (0, 140, 60), (120, 120, 120), (170, 170, 170))  # fmt: skip

# Concentration colour map (after ColorBrewer YlOrRd): light yellow at the low end, so the plume's
# faint edge never darkens the scene, dark red at the core.
_CONC_X = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
_CONC_RGB = np.array([[255, 245, 180], [254, 204, 92], [253, 141, 60], [227, 26, 28], [128, 0, 38]], dtype=float)

# Wind speed colour map (after ColorBrewer GnBu, its light end pale): calm air light, fast air
# teal-blue; unlike the plume's yellow-red, and drawn translucent under everything else.
_WIND_X = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
_WIND_RGB = np.array([[247, 252, 240], [204, 235, 197], [123, 204, 196], [43, 140, 190], [8, 64, 129]], dtype=float)


def speed_colormap(v: np.ndarray, v_max: float) -> np.ndarray:
    """Wind speeds [m/s] to RGB (N, 3) uint8 on a linear scale from 0 to ``v_max`` (clipped)."""
    s = np.clip(np.ravel(np.asarray(v, dtype=float)) / max(float(v_max), 1e-9), 0.0, 1.0)
    rgb = np.column_stack([np.interp(s, _WIND_X, _WIND_RGB[:, k]) for k in range(3)])
    return np.round(rgb).astype(np.uint8)


def state_color(state: str) -> Rgb:
    """The path colour of a strategy state or flight phase (a stable fallback for unknown names)."""
    c = STATE_COLORS.get(state)
    if c is not None:
        return c
    return _FALLBACK[sum(state.encode()) % len(_FALLBACK)]


def log_scale(c: np.ndarray, c_min: float, c_max: float) -> np.ndarray:
    """Concentrations [mg/m^3] as positions 0..1 on a log10 scale from ``c_min`` to ``c_max`` (clipped)."""
    c = np.asarray(c, dtype=float)
    lo, hi = math.log10(c_min), math.log10(c_max)
    s = (np.log10(np.maximum(c, c_min)) - lo) / (hi - lo)
    return np.clip(s, 0.0, 1.0)


def log_colormap(c: np.ndarray, c_min: float, c_max: float) -> np.ndarray:
    """Concentrations [mg/m^3] to RGB (N, 3) uint8 on a log10 scale between ``c_min`` and ``c_max``.

    A log scale because a plume spans decades between its core and its edge; values at or below
    ``c_min`` get the lowest (lightest) colour, at or above ``c_max`` the highest (darkest).
    """
    s = log_scale(np.ravel(c), c_min, c_max)
    rgb = np.column_stack([np.interp(s, _CONC_X, _CONC_RGB[:, k]) for k in range(3)])
    return np.round(rgb).astype(np.uint8)


def conc_image(conc_ne: np.ndarray, c_min: float, c_max: float, alpha_max: int = 200) -> np.ndarray:
    """A north-up RGBA image (H = north cells, W = east cells, uint8) of a concentration grid
    ``conc_ne[i, j]`` (i north ascending, j east ascending) [mg/m^3]: colour on the log scale,
    opacity rising with it from 0 at ``c_min`` (cells below are transparent), so the map under the
    plume's edge stays visible."""
    c = np.asarray(conc_ne, dtype=float)[::-1, :]  # image row 0 is the northmost cell
    s = log_scale(c, c_min, c_max)
    rgba = np.empty((*c.shape, 4), dtype=np.uint8)
    rgba[..., :3] = log_colormap(c, c_min, c_max).reshape(*c.shape, 3)
    alpha = np.where(c >= c_min, 60.0 + (alpha_max - 60.0) * s, 0.0)
    rgba[..., 3] = np.round(alpha).astype(np.uint8)
    return rgba


def posterior_alpha(p_ne: np.ndarray, alpha_max: int = 190) -> np.ndarray:
    """The opacity (uint8, H x W, row 0 the northmost) with which :func:`posterior_image` draws a
    probability grid ``p_ne[i, j]`` (i north, j east): proportional to the square root of the
    probability relative to the grid's maximum (an empty grid is transparent)."""
    p = np.asarray(p_ne, dtype=float)[::-1, :]
    top = float(np.max(p)) if p.size else 0.0
    s = np.clip(p / top, 0.0, 1.0) if top > 0.0 and math.isfinite(top) else np.zeros_like(p)
    return np.round(alpha_max * np.sqrt(s)).astype(np.uint8)  # sqrt: the tails stay visible


def posterior_image(p_ne: np.ndarray, alpha_max: int = 190) -> np.ndarray:
    """A north-up RGBA image of a probability grid ``p_ne[i, j]`` (i north, j east): purple, opacity
    :func:`posterior_alpha` (the recording sends it as an indexed PNG, :func:`recording.png.alpha_png`)."""
    a = posterior_alpha(p_ne, alpha_max)
    rgba = np.empty((*a.shape, 4), dtype=np.uint8)
    rgba[..., :3] = C_POSTERIOR
    rgba[..., 3] = a
    return rgba


__all__ = [
    "AXES", "C_AUTOPILOT", "C_AXES3", "C_BAND", "C_BUILDING", "C_BUILDING_EDGE", "C_BUILDING_MAP", "C_DECLARED",
    "C_EST", "C_FENCE", "C_FIELD_ARROW", "C_FURNITURE", "C_GPS", "C_MAP_EST", "C_MAP_TRUTH", "C_MARK_DECLARED",
    "C_MARK_PHASE", "C_MARK_VERIFY", "C_POSTERIOR", "C_RAW", "C_ROTORS", "C_SOURCE", "C_THRESH", "C_TRAIL_3D",
    "C_TRUTH", "C_VEHICLE", "PHASES", "PHASE_COLORS", "SCENE_BACKGROUND", "STATE_COLORS", "STATE_TEXT", "TEXT_LEVELS",
    "TIMELINE", "VecLike", "conc_image", "log_colormap", "log_scale", "posterior_alpha", "posterior_image",
    "speed_colormap", "state_color",
]  # fmt: skip
