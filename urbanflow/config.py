"""Validated configuration of an urban wind scene: buildings, upstream wind profile, grid, options.

Conventions: SI units; local NED frame (x north, y east, z down) with the ground at z = 0, but
every height in this configuration is a positive number of metres above the ground. Angles are
in degrees here (they come from scenario files); a wind direction is the meteorological
from-direction (0 = from north, 90 = from east) and the wind vector is the air-mass velocity:
a wind from 45 deg blows toward the south-west, ``speed * [-cos 45, -sin 45, 0]`` NED.

Every dataclass validates itself on construction and raises :class:`ConfigError`, whose message
names the field: ``buildings[2].height_m = -3.0: must be > 0``. Containers prefix the path of
their members, so the message always says where the bad value is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

Vec2 = tuple[float, float]

# Beyond this the arrays of one field (about 10 float64 per cell) no longer fit a workstation.
MAX_GRID_CELLS = 40_000_000


class ConfigError(ValueError):
    """A bad configuration value; ``path`` names the field (``buildings[2].height_m``)."""

    def __init__(self, path: str, value: Any, reason: str) -> None:
        self.path = path
        self.value = value
        self.reason = reason
        super().__init__(f"{path} = {value!r}: {reason}")

    def prefixed(self, prefix: str) -> ConfigError:
        """The same error with ``prefix.`` in front of its path."""
        return ConfigError(f"{prefix}.{self.path}" if self.path else prefix, self.value, self.reason)


def _num(path: str, value: Any, reason: str, ok: Any = None) -> float:
    """``value`` as a finite float for which ``ok(v)`` holds, else :class:`ConfigError`."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(path, value, f"must be a number; {reason}") from None
    if not math.isfinite(v) or (ok is not None and not ok(v)):
        raise ConfigError(path, value, reason)
    return v


def _set(obj: object, name: str, value: object) -> None:
    object.__setattr__(obj, name, value)


@dataclass(frozen=True)
class BoxBuilding:
    """A flat-roofed rectangular block standing on the ground.

    Attributes:
        x_m, y_m: NED north / east position (m) of the anchor point.
        length_m: extent along the box's own axis (m, > 0); the axis points north when
            ``rotation_deg`` is 0.
        width_m: extent across the axis (m, > 0); east when ``rotation_deg`` is 0.
        height_m: roof height above the ground (m, > 0).
        rotation_deg: rotation of the axis about the vertical, clockwise seen from above
            (north toward east, like a heading), degrees.
        anchor: ``"center"``: (x_m, y_m) is the footprint's centre; ``"corner"``: it is the
            corner with the smallest local coordinates (the south-west corner when unrotated).
        name: free label for messages and plots.
    """

    x_m: float
    y_m: float
    length_m: float
    width_m: float
    height_m: float
    rotation_deg: float = 0.0
    anchor: str = "center"
    name: str = ""

    def __post_init__(self) -> None:
        _set(self, "x_m", _num("x_m", self.x_m, "must be a finite north position (m)"))
        _set(self, "y_m", _num("y_m", self.y_m, "must be a finite east position (m)"))
        for attr in ("length_m", "width_m", "height_m"):
            _set(self, attr, _num(attr, getattr(self, attr), "must be > 0 (m)", lambda v: v > 0))
        _set(self, "rotation_deg", _num("rotation_deg", self.rotation_deg, "must be a finite angle (deg)"))
        if self.anchor not in ("center", "corner"):
            raise ConfigError("anchor", self.anchor, "must be 'center' or 'corner'")

    def footprint(self) -> np.ndarray:
        """Footprint corners (4, 2), NED (north, east) m, counter-clockwise in the (x, y) plane."""
        r = math.radians(self.rotation_deg)
        ax = np.array([math.cos(r), math.sin(r)])  # the box axis (length direction)
        ay = np.array([-math.sin(r), math.cos(r)])  # across (width direction)
        origin = np.array([self.x_m, self.y_m])
        if self.anchor == "center":
            origin = origin - 0.5 * self.length_m * ax - 0.5 * self.width_m * ay
        la, wa = self.length_m * ax, self.width_m * ay
        return np.array([origin, origin + la, origin + la + wa, origin + wa])


def _segments_cross(p1: np.ndarray, p2: np.ndarray, q1: np.ndarray, q2: np.ndarray) -> bool:
    """True if the open segments p1-p2 and q1-q2 properly cross (shared end points do not count)."""

    def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
        return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    d1, d2 = orient(q1, q2, p1), orient(q1, q2, p2)
    d3, d4 = orient(p1, p2, q1), orient(p1, p2, q2)
    return d1 * d2 < 0 and d3 * d4 < 0


@dataclass(frozen=True)
class PolygonBuilding:
    """A flat-roofed building whose footprint is a simple polygon, extruded from the ground.

    Attributes:
        vertices_m: footprint corners as (north, east) pairs in m, at least 3, in either order
            (stored counter-clockwise in the (x, y) plane), no self-intersection, no repeated
            closing vertex.
        height_m: roof height above the ground (m, > 0).
        name: free label.
    """

    vertices_m: tuple[Vec2, ...]
    height_m: float
    name: str = ""

    def __post_init__(self) -> None:
        try:
            arr = np.asarray(self.vertices_m, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError("vertices_m", self.vertices_m, "must be a list of (north, east) pairs in m") from None
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3 or not np.all(np.isfinite(arr)):
            raise ConfigError("vertices_m", self.vertices_m, "must be at least 3 finite (north, east) pairs in m")
        n = arr.shape[0]
        area = 0.5 * float(np.sum(arr[:, 0] * np.roll(arr[:, 1], -1) - np.roll(arr[:, 0], -1) * arr[:, 1]))
        if abs(area) < 1e-6:
            raise ConfigError("vertices_m", self.vertices_m, "must enclose a non-zero area")
        for i in range(n):
            if np.allclose(arr[i], arr[(i + 1) % n]):
                raise ConfigError(f"vertices_m[{i}]", tuple(arr[i]), "repeats the next vertex")
            for j in range(i + 2, n):
                if i == 0 and j == n - 1:
                    continue  # neighbours through the closing edge
                if _segments_cross(arr[i], arr[(i + 1) % n], arr[j], arr[(j + 1) % n]):
                    raise ConfigError("vertices_m", self.vertices_m, f"edges {i} and {j} cross (self-intersecting)")
        if area < 0:
            arr = arr[::-1]
        _set(self, "vertices_m", tuple((float(a), float(b)) for a, b in arr))
        _set(self, "height_m", _num("height_m", self.height_m, "must be > 0 (m)", lambda v: v > 0))

    def footprint(self) -> np.ndarray:
        """Footprint corners (N, 2), NED (north, east) m, counter-clockwise in the (x, y) plane."""
        return np.array(self.vertices_m, dtype=np.float64)


Building = BoxBuilding | PolygonBuilding


@dataclass(frozen=True)
class LogWindProfile:
    """Upstream neutral log-law wind: U(h) = (u*/kappa) ln((h - d) / z0), 0 below d + z0.

    Attributes:
        speed_m_s: U at ``reference_height_m`` (m/s, >= 0).
        from_deg: meteorological from-direction (deg): 45 = from the north-east.
        reference_height_m: z_ref (m above ground, > d + z0).
        roughness_length_m: z0 (m, > 0). The paper gives none; 0.1 m is the project's default.
        displacement_m: zero-plane displacement d (m, >= 0); 0 keeps the profile identical to
            the open-field log profile of :mod:`sitl.world.wind`.
    """

    speed_m_s: float = 7.0
    from_deg: float = 45.0
    reference_height_m: float = 10.0
    roughness_length_m: float = 0.1
    displacement_m: float = 0.0

    def __post_init__(self) -> None:
        _set(self, "speed_m_s", _num("speed_m_s", self.speed_m_s, "must be >= 0 (m/s)", lambda v: v >= 0))
        _set(self, "from_deg", _num("from_deg", self.from_deg, "must be a finite angle (deg)"))
        z0 = _num("roughness_length_m", self.roughness_length_m, "must be > 0 (m)", lambda v: v > 0)
        d = _num("displacement_m", self.displacement_m, "must be >= 0 (m)", lambda v: v >= 0)
        zr = _num(
            "reference_height_m",
            self.reference_height_m,
            f"must exceed displacement_m + roughness_length_m = {d + z0} (m)",
            lambda v: v > d + z0,
        )
        _set(self, "roughness_length_m", z0)
        _set(self, "displacement_m", d)
        _set(self, "reference_height_m", zr)

    @property
    def direction_ned(self) -> Vec2:
        """Unit horizontal direction the air moves toward, (north, east)."""
        r = math.radians(self.from_deg)
        return (-math.cos(r), -math.sin(r))

    @property
    def friction_velocity_m_s(self) -> float:
        """u* = kappa U_ref / ln((z_ref - d) / z0) with kappa = 0.4 (m/s)."""
        ref = (self.reference_height_m - self.displacement_m) / self.roughness_length_m
        return 0.4 * self.speed_m_s / math.log(ref)

    def speed_at(self, height_m: float | np.ndarray) -> np.ndarray:
        """U(h) in m/s at heights above ground (m); 0 at and below d + z0."""
        h = np.asarray(height_m, dtype=np.float64)
        arg = np.maximum((h - self.displacement_m) / self.roughness_length_m, 1.0)
        ref = math.log((self.reference_height_m - self.displacement_m) / self.roughness_length_m)
        return self.speed_m_s * np.log(arg) / ref


@dataclass(frozen=True)
class GridSpec:
    """The staggered (MAC) grid of the field: a box of cells from the ground up.

    Attributes:
        x_min_m, y_min_m: NED north / east of the grid's south-west corner (m).
        length_x_m, length_y_m: extents north and east (m), multiples of ``spacing_m``.
        height_m: grid top above ground (m), a multiple of ``vertical_spacing_m``; the top
            should be at least 2.5-3 times the tallest building (QUIC-URB practice).
        spacing_m: horizontal cell size dx = dy (m, > 0).
        vertical_spacing_m: dz (m); None: equal to ``spacing_m``.
    """

    x_min_m: float
    y_min_m: float
    length_x_m: float
    length_y_m: float
    height_m: float
    spacing_m: float
    vertical_spacing_m: float | None = None

    def __post_init__(self) -> None:
        _set(self, "x_min_m", _num("x_min_m", self.x_min_m, "must be a finite north position (m)"))
        _set(self, "y_min_m", _num("y_min_m", self.y_min_m, "must be a finite east position (m)"))
        dx = _num("spacing_m", self.spacing_m, "must be > 0 (m)", lambda v: v > 0)
        dz = dx if self.vertical_spacing_m is None else self.vertical_spacing_m
        dz = _num("vertical_spacing_m", dz, "must be > 0 (m)", lambda v: v > 0)
        _set(self, "spacing_m", dx)
        _set(self, "vertical_spacing_m", dz)
        for attr, step, step_name in (
            ("length_x_m", dx, "spacing_m"),
            ("length_y_m", dx, "spacing_m"),
            ("height_m", dz, "vertical_spacing_m"),
        ):
            v = _num(attr, getattr(self, attr), "must be > 0 (m)", lambda v: v > 0)
            n = round(v / step)
            if n < 4 or abs(n * step - v) > 1e-6 * max(v, 1.0):
                raise ConfigError(attr, v, f"must be a multiple (>= 4) of {step_name} = {step} m")
            _set(self, attr, v)
        if self.n_cells > MAX_GRID_CELLS:
            raise ConfigError("spacing_m", dx, f"gives {self.n_cells} cells, more than {MAX_GRID_CELLS}")

    @property
    def shape(self) -> tuple[int, int, int]:
        """(nx, ny, nz) cells: north, east, up."""
        dz = float(self.vertical_spacing_m or self.spacing_m)
        return (
            round(self.length_x_m / self.spacing_m),
            round(self.length_y_m / self.spacing_m),
            round(self.height_m / dz),
        )

    @property
    def n_cells(self) -> int:
        nx, ny, nz = self.shape
        return nx * ny * nz

    @property
    def dz(self) -> float:
        return float(self.vertical_spacing_m or self.spacing_m)


@dataclass(frozen=True)
class UrbanOptions:
    """Switches and constants of the building parameterizations and the solver.

    Attributes:
        upwind, rooftop, wake, street_canyon: turn each parameterization on/off.
        upwind_length_coeff: L_F = c W cos(theta) / (1 + 0.8 W / H); 1.5 is the modified vortex
            parameterization (MVP, Bagal et al. 2004), 2.0 Roeckle's original.
        upwind_max_incidence_deg: a face gets an upwind zone when the wind meets it within this
            angle of its normal (deg). 50 keeps both faces of a box hit corner-on at 45 deg.
        rooftop_max_incidence_deg: the rooftop vortex needs the leading face within this angle
            of the wind (30 deg, as QES-Winds).
        far_wake_factor: the far wake ends at this many cavity lengths (3, Roeckle).
        alpha_ratio: (alpha1 / alpha2) of the variational weights; 1 = isotropic adjustment
            (QUIC-URB default); larger lets the solver change w more freely.
        solver_tol: relative residual of the Poisson solve (1e-8 gives a largest divergence of
            about 1e-8 U_ref / dx).
        amg: multigrid preconditioner, ``"classical"`` (Ruge-Stueben, faster here) or
            ``"smoothed_aggregation"``.
        wake_turbulence_enhancement: turbulence floor in cavities, canyons and rooftop vortices:
            the multiplier is at least this times U_H / U_ref there (see :mod:`.field`).
    """

    upwind: bool = True
    rooftop: bool = True
    wake: bool = True
    street_canyon: bool = True
    upwind_length_coeff: float = 1.5
    upwind_max_incidence_deg: float = 50.0
    rooftop_max_incidence_deg: float = 30.0
    far_wake_factor: float = 3.0
    alpha_ratio: float = 1.0
    solver_tol: float = 1e-8
    amg: str = "classical"
    wake_turbulence_enhancement: float = 1.5

    def __post_init__(self) -> None:
        for attr in ("upwind", "rooftop", "wake", "street_canyon"):
            if not isinstance(getattr(self, attr), bool):
                raise ConfigError(attr, getattr(self, attr), "must be true or false")
        checks: dict[str, tuple[str, Any]] = {
            "upwind_length_coeff": ("must be > 0", lambda v: v > 0),
            "upwind_max_incidence_deg": ("must be in [0, 90) deg", lambda v: 0 <= v < 90),
            "rooftop_max_incidence_deg": ("must be in [0, 90) deg", lambda v: 0 <= v < 90),
            "far_wake_factor": ("must be >= 1", lambda v: v >= 1),
            "alpha_ratio": ("must be > 0", lambda v: v > 0),
            "solver_tol": ("must be in (0, 1e-3]", lambda v: 0 < v <= 1e-3),
            "wake_turbulence_enhancement": ("must be >= 0", lambda v: v >= 0),
        }
        for attr, (reason, ok) in checks.items():
            _set(self, attr, _num(attr, getattr(self, attr), reason, ok))
        if self.amg not in ("classical", "smoothed_aggregation"):
            raise ConfigError("amg", self.amg, "must be 'classical' or 'smoothed_aggregation'")


@dataclass(frozen=True)
class UrbanScene:
    """Everything that determines an urban mean wind field (and its cache key).

    Buildings must stand inside the grid horizontally, below its top, and at least one cell
    away from its sides (the sides are open inflow/outflow boundaries).
    """

    buildings: tuple[Building, ...]
    wind: LogWindProfile
    grid: GridSpec
    options: UrbanOptions = field(default_factory=UrbanOptions)
    name: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.buildings, Sequence) or isinstance(self.buildings, str):
            raise ConfigError("buildings", self.buildings, "must be a list of BoxBuilding / PolygonBuilding")
        _set(self, "buildings", tuple(self.buildings))
        for name, cls in (("wind", LogWindProfile), ("grid", GridSpec), ("options", UrbanOptions)):
            if not isinstance(getattr(self, name), cls):
                raise ConfigError(name, getattr(self, name), f"must be a {cls.__name__}")
        g = self.grid
        for i, b in enumerate(self.buildings):
            if not isinstance(b, BoxBuilding | PolygonBuilding):
                raise ConfigError(f"buildings[{i}]", b, "must be a BoxBuilding or a PolygonBuilding")
            fp = b.footprint()
            lo, hi = fp.min(axis=0), fp.max(axis=0)
            margin = g.spacing_m
            if (
                lo[0] < g.x_min_m + margin
                or hi[0] > g.x_min_m + g.length_x_m - margin
                or lo[1] < g.y_min_m + margin
                or hi[1] > g.y_min_m + g.length_y_m - margin
            ):
                raise ConfigError(
                    f"buildings[{i}]",
                    b.name or type(b).__name__,
                    f"footprint north {lo[0]:.1f}..{hi[0]:.1f} m, east {lo[1]:.1f}..{hi[1]:.1f} m must lie inside "
                    f"the grid (north {g.x_min_m}..{g.x_min_m + g.length_x_m} m, east {g.y_min_m}.."
                    f"{g.y_min_m + g.length_y_m} m) with one cell to spare",
                )
            if b.height_m > g.height_m - g.dz:
                top = f"must be at least one cell below the grid top ({g.height_m} m)"
                raise ConfigError(f"buildings[{i}].height_m", b.height_m, top)
