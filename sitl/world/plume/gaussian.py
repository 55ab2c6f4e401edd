"""The time-averaged Gaussian plume: Briggs open-country spreads, ground reflection, virtual source.

The formulas are tabulated for 100 m < x < 10 km; they are extrapolated to shorter range
(linear in x there, which is what short-range Taylor dispersion gives). A source size
``source_radius_m`` is added in quadrature so the field is finite at the source. This is the
reference for the puff model and a cheap likelihood model for strategies.

Units: m, s, m/s; NED; wind = air-mass velocity; release g/s; concentration mg/m^3.
"""

from __future__ import annotations

import math

import numpy as np

from sitl.world.plume.config import G_TO_MG, STABILITY_CLASSES, PlumeConfig, WindLike, check_config

# Briggs (1973) open-country coefficients: sigma = a * x * (1 + b * x) ** p, x in m.
BRIGGS_Y: dict[str, tuple[float, float, float]] = {
    "A": (0.22, 1e-4, -0.5),
    "B": (0.16, 1e-4, -0.5),
    "C": (0.11, 1e-4, -0.5),
    "D": (0.08, 1e-4, -0.5),
    "E": (0.06, 1e-4, -0.5),
    "F": (0.04, 1e-4, -0.5),
}
BRIGGS_Z: dict[str, tuple[float, float, float]] = {
    "A": (0.20, 0.0, 0.0),
    "B": (0.12, 0.0, 0.0),
    "C": (0.08, 2e-4, -0.5),
    "D": (0.06, 1.5e-3, -0.5),
    "E": (0.03, 3e-4, -1.0),
    "F": (0.016, 3e-4, -1.0),
}



def briggs_sigmas(x_m: np.ndarray, stability: str) -> tuple[np.ndarray, np.ndarray]:
    """Briggs open-country sigma_y, sigma_z [m] at downwind distance ``x_m`` [m] (>= 0)."""
    x = np.maximum(np.asarray(x_m, dtype=float), 0.0)
    ay, by, py = BRIGGS_Y[stability]
    az, bz, pz = BRIGGS_Z[stability]
    return ay * x * (1.0 + by * x) ** py, az * x * (1.0 + bz * x) ** pz


def gaussian_plume_concentration(
    points_ned: np.ndarray,
    source_ned: np.ndarray,
    rate_g_s: float,
    wind_ned: np.ndarray,
    stability: str = "D",
    source_radius_m: float = 0.3,
    min_wind_speed_m_s: float = 0.5,
) -> np.ndarray | float:
    """Steady Gaussian plume concentration [mg/m^3] with ground reflection.

    points_ned: (N,3) or (3,) query points, NED [m].
    source_ned: (3,) release point, NED [m].
    rate_g_s: release rate [g/s].
    wind_ned: mean air-mass velocity NED [m/s]; only its horizontal part is used
        (direction = where the plume goes, speed = dilution, floored at
        ``min_wind_speed_m_s``).
    stability: Pasquill-Gifford class "A".."F".
    source_radius_m: virtual source size added in quadrature to both sigmas [m].

    Returns (N,) or a float for a (3,) input; zero upwind of the source.
    """
    if stability not in STABILITY_CLASSES:
        raise ValueError(f"stability: one of {', '.join(STABILITY_CLASSES)}, got {stability!r}")
    pts = np.asarray(points_ned, dtype=float)
    single = pts.ndim == 1
    pts = np.atleast_2d(pts)
    src = np.asarray(source_ned, dtype=float)
    w = np.asarray(wind_ned, dtype=float)
    speed_h = math.hypot(w[0], w[1])
    u = max(speed_h, min_wind_speed_m_s)
    # With no horizontal wind there is no direction; keep a deterministic one (north).
    e_along = np.array([w[0], w[1]]) / speed_h if speed_h > 1e-9 else np.array([1.0, 0.0])
    e_cross = np.array([-e_along[1], e_along[0]])
    d = pts[:, :2] - src[:2]
    x_down = d @ e_along
    y_cross = d @ e_cross
    sy, sz = briggs_sigmas(x_down, stability)
    r02 = source_radius_m**2
    sy2 = sy**2 + r02
    sz2 = sz**2 + r02
    h = -src[2]
    z = -pts[:, 2]
    conc = (
        rate_g_s
        * G_TO_MG
        / (2.0 * math.pi * u * np.sqrt(sy2 * sz2))
        * np.exp(-0.5 * y_cross**2 / sy2)
        * (np.exp(-0.5 * (z - h) ** 2 / sz2) + np.exp(-0.5 * (z + h) ** 2 / sz2))
    )
    conc = np.where(x_down > 0.0, conc, 0.0)
    return float(conc[0]) if single else conc


class GaussianPlume:
    """Time-averaged plume with the same ``step``/``concentration`` interface as PuffPlume.

    ``step`` only advances time: it samples the mean wind at each source and tracks
    source timing. A source that switches on at start_s fills the plume from the
    source outward at the wind speed (front at u*(t - start_s)); after stop_s the tail
    leaves the same way, so the on/off timing is visible to a vehicle downwind.
    """

    def __init__(
        self, config: PlumeConfig, wind: WindLike, seed: int | np.random.SeedSequence | None = None, t0: float = 0.0
    ):
        """config: validated PlumeConfig; wind: wind model; seed: unused (deterministic
        model), accepted for a uniform factory signature; t0: initial time [s]."""
        check_config(config)
        self.config = config
        self._wind = wind
        self._src = np.array([s.position_ned for s in config.sources], dtype=float)
        self._t = t0
        self._winds = np.zeros((len(config.sources), 3))
        self._sample_winds()

    @property
    def t(self) -> float:
        """Current plume time [s]."""
        return self._t

    def _sample_winds(self) -> None:
        for i, p in enumerate(self._src):
            self._winds[i] = self._wind.mean(self._t, p)

    def step(self, t: float, dt: float) -> None:
        """Advance from ``t`` to ``t + dt`` [s]."""
        self._t = t + dt
        self._sample_winds()

    def concentration(self, points: np.ndarray) -> np.ndarray | float:
        """Concentration [mg/m^3] at (N,3) NED points -> (N,), or (3,) -> float."""
        pts = np.asarray(points, dtype=float)
        single = pts.ndim == 1
        pts = np.atleast_2d(pts)
        total = np.zeros(len(pts))
        cfg = self.config
        for i, s in enumerate(cfg.sources):
            if self._t < s.start_s:
                continue
            w = self._winds[i]
            c = gaussian_plume_concentration(
                pts,
                self._src[i],
                s.rate_g_s,
                w,
                cfg.stability,
                cfg.source_radius_m,
                cfg.min_wind_speed_m_s,
            )
            # Limit the plume to air released while the source was on.
            speed_h = math.hypot(w[0], w[1])
            u = max(speed_h, cfg.min_wind_speed_m_s)
            e = np.array([w[0], w[1]]) / speed_h if speed_h > 1e-9 else np.array([1.0, 0.0])
            x_down = (pts[:, :2] - self._src[i, :2]) @ e
            on = x_down <= u * (self._t - s.start_s)
            if math.isfinite(s.stop_s):
                on &= x_down >= u * (self._t - s.stop_s)
            total += np.where(on, c, 0.0)
        return float(total[0]) if single else total

    def slice_grid(
        self, z: float, x_range: tuple[float, float], y_range: tuple[float, float], n: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Horizontal slice at NED depth ``z`` [m]: returns xs (n,), ys (n,), C (n,n)
        with C[i, j] the concentration [mg/m^3] at (xs[i], ys[j], z)."""
        return concentration_slice(self.concentration, z, x_range, y_range, n)


def concentration_slice(conc_fn, z, x_range, y_range, n):
    xs = np.linspace(x_range[0], x_range[1], n)
    ys = np.linspace(y_range[0], y_range[1], n)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    pts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, float(z))])
    return xs, ys, np.asarray(conc_fn(pts)).reshape(n, n)
