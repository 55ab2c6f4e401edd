"""The instantaneous puff (filament) plume, Farrell et al. (2002) style; the plume factory.

See :mod:`sitl.world.plume` for the model and its calibration; units m, s, m/s; NED;
release g/s; concentration mg/m^3.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

from sitl.world.kernel import NO_OBSTACLES, Obstacles, compiled_entry
from sitl.world.plume.config import G_TO_MG, TWO_PI_POW_1_5, PlumeConfig, WindLike, check_config
from sitl.world.plume.gaussian import BRIGGS_Y, BRIGGS_Z, GaussianPlume, concentration_slice
from sitl.world.plume.meander import (
    MEANDER_REFRESH_S,
    PUFF_GROWTH_SHARE,
    MeanderField,
    axis_calibration,
    frozen_turbulence_variances,
)
from sitl.world.plume.store import PuffStore
from sitl.world.plume.substep import NormalBlock, advance_puffs, physical_positions, puff_substep
from sitl.world.wind.kernel import wind_mean
from urbanflow.geometry import building_at, reflect_point

# ---------------------------------------------------------------------------------- kernels
# The puff update and the concentration sum are the plume's hot loops (called at the plume
# and sensor rates inside a simulator that must run >= 100x real time): fused numba loops,
# no (K,M) or (N,K) temporaries. Per-puff arithmetic is the formula of the docstrings above.


@njit(cache=True)
def _reflect_puffs(
    pos: np.ndarray, before: np.ndarray, verts: np.ndarray, offsets: np.ndarray, heights: np.ndarray,
    bbox: np.ndarray,
) -> int:  # fmt: skip
    """In place: puffs ``pos`` (N, 3: north, east m, unfolded altitude m up; the physical height is
    its absolute value) whose step from ``before`` (N, 3 NED m) ended inside a building, reflected
    out of it (:func:`reflect_point`), with the reflected height as their new altitude. Returns how
    many were inside. One pass in compiled code: the plume does this at every update."""
    moved = 0
    for k in range(pos.shape[0]):
        px, py, ph = pos[k, 0], pos[k, 1], abs(pos[k, 2])
        if building_at(px, py, ph, verts, offsets, heights, bbox) < 0:
            continue
        moved += 1
        rx, ry, rh = reflect_point(before[k, 0], before[k, 1], -before[k, 2], px, py, ph, verts, offsets, heights, bbox)
        if rx != px or ry != py or rh != ph:
            pos[k, 0], pos[k, 1], pos[k, 2] = rx, ry, rh
    return moved


#: Query points from which :func:`_puff_concentration` first culls the puffs against their bounding box.
CULL_MIN_POINTS = 16


@njit(cache=True)
def _puff_concentration(pts: np.ndarray, pos: np.ndarray, r2: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Sum of ground-reflected isotropic Gaussian puffs [mg/m^3] at NED points pts (N,3) [m].

    pos (K,3): x, y NED and unfolded altitude [m] (|altitude| is physical); r2 (K,) puff
    variance [m^2]; mass (K,) [g]."""
    n = pts.shape[0]
    kp = pos.shape[0]
    out = np.zeros(n)
    inv = np.empty(kp)
    norm = np.empty(kp)
    for j in range(kp):
        inv[j] = -0.5 / r2[j]
        norm[j] = mass[j] * G_TO_MG / (TWO_PI_POW_1_5 * r2[j] * math.sqrt(r2[j]))
    # A puff whose horizontal factor is below e^-40 adds < 5e-18 of its peak and is skipped. For a
    # grid (a recorded slice: a few thousand points, of which most puffs, drifted far downwind,
    # reach none) the puffs are first culled against the points' bounding box with the same test:
    # no point is nearer a puff than the box, and float subtraction, squares and sums are monotone,
    # so a culled puff fails the per-point test for every point and the sums are bit for bit the same.
    used = np.arange(kp)
    if n >= CULL_MIN_POINTS:
        xlo, xhi, ylo, yhi = pts[0, 0], pts[0, 0], pts[0, 1], pts[0, 1]
        for i in range(1, n):
            xlo, xhi = min(xlo, pts[i, 0]), max(xhi, pts[i, 0])
            ylo, yhi = min(ylo, pts[i, 1]), max(yhi, pts[i, 1])
        m = 0
        for j in range(kp):
            bx = max(xlo - pos[j, 0], pos[j, 0] - xhi, 0.0)
            by = max(ylo - pos[j, 1], pos[j, 1] - yhi, 0.0)
            if not (bx * bx + by * by) * inv[j] < -40.0:
                used[m] = j
                m += 1
        used = used[:m]
    for i in range(n):
        zq = -pts[i, 2]
        acc = 0.0
        for q in used:
            dx = pts[i, 0] - pos[q, 0]
            dy = pts[i, 1] - pos[q, 1]
            dh2 = dx * dx + dy * dy
            zp = abs(pos[q, 2])
            e = dh2 * inv[q]
            if e < -40.0:  # saves the two exp calls (most puffs are far from a point)
                continue
            dzm = zq - zp
            dzp = zq + zp
            acc += norm[q] * (math.exp(e + dzm * dzm * inv[q]) + math.exp(e + dzp * dzp * inv[q]))
        out[i] = acc
    return out


@njit(cache=True)
def _puff_concentration_at(px: float, py: float, pz: float, pos: np.ndarray, r2: np.ndarray, mass: np.ndarray) -> float:
    """:func:`_puff_concentration` at one NED point (px, py, pz) [m] (mg/m^3): the same terms in the same order,
    without the arrays (the chemical sensor's reading, at the sensor rate)."""
    zq = -pz
    acc = 0.0
    for q in range(pos.shape[0]):
        inv = -0.5 / r2[q]
        dx = px - pos[q, 0]
        dy = py - pos[q, 1]
        e = (dx * dx + dy * dy) * inv
        if e < -40.0:
            continue
        zp = abs(pos[q, 2])
        dzm = zq - zp
        dzp = zq + zp
        norm = mass[q] * G_TO_MG / (TWO_PI_POW_1_5 * r2[q] * math.sqrt(r2[q]))
        acc += norm * (math.exp(e + dzm * dzm * inv) + math.exp(e + dzp * dzp * inv))
    return acc


class PuffPlume:
    """Instantaneous puff (filament) plume, Farrell et al. (2002) style.

    State: puff centres (x, y NED [m] and an *unfolded* altitude [m] whose absolute
    value is the physical altitude: reflection at the ground, the puff analogue of the
    image source), puff variances r^2 [m^2], masses [g], release times [s].
    """

    def __init__(
        self,
        config: PlumeConfig,
        wind: WindLike,
        seed: int | np.random.SeedSequence,
        t0: float = 0.0,
        obstacles: Obstacles = NO_OBSTACLES,
    ):
        """config: plume configuration (validated, ValueError lists the problems);
        obstacles: buildings the puffs are reflected off (never inside one);
        wind: object with ``mean(t, pos)`` and ``velocity(t, positions)``;
        seed: int or SeedSequence for every random process; t0: initial time [s]."""
        check_config(config)
        self.config = config
        self._wind = wind
        self._obstacles = obstacles
        self.reflected = 0  # puff steps mirrored out of a building
        ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        ss_walk, ss_modes_h, ss_modes_v = ss.spawn(3)
        self._rng = np.random.default_rng(ss_walk)
        self._meander = MeanderField(
            np.random.default_rng(ss_modes_h), np.random.default_rng(ss_modes_v)
        )
        # Each puff re-samples the meander every MEANDER_REFRESH_S, a 1/n_groups share of
        # the puffs per substep (constant cost per step).
        self._n_groups = max(1, round(MEANDER_REFRESH_S * config.update_rate_hz))
        self._substep_count = 0
        self._next_serial = 0
        self._src = np.array([s.position_ned for s in config.sources], dtype=float)
        self._src0 = self._src[0].copy()
        self._puff_mass_g = np.array([s.rate_g_s / config.puff_rate_hz for s in config.sources])
        self._n_released = np.zeros(len(config.sources), dtype=np.int64)
        self._t = float(t0)
        self._cy = BRIGGS_Y[config.stability]
        self._cz = BRIGGS_Z[config.stability]
        self._frozen_var = (
            frozen_turbulence_variances(wind) if config.subtract_wind_turbulence else (0.0, 0.0)
        )
        if config.domain_min_ned is not None:
            self._dom_lo: np.ndarray | None = np.asarray(config.domain_min_ned, dtype=float)
            self._dom_hi: np.ndarray | None = np.asarray(config.domain_max_ned, dtype=float)
        else:
            self._dom_lo = self._dom_hi = None  # no domain: puffs are kept wherever they go
        self._store = PuffStore()  # x, y NED, unfolded altitude (up) [m]; r^2; mass; release time; ...
        self._phys = np.zeros((0, 3))  # the puffs' physical positions at a substep's start (grown as needed)
        self._normals = NormalBlock(self._rng)  # the random-walk normals, drawn ahead
        self._cal_key: tuple[float, float] | None = None
        self._cal = np.zeros(7)
        self._substep_fn: Callable[..., None] | None = None
        self.released_mass_g = 0.0
        self.removed_domain_mass_g = 0.0
        self.removed_cap_mass_g = 0.0

    # ------------------------------------------------------------------ state
    @property
    def t(self) -> float:
        """Current plume time [s]."""
        return self._t

    @property
    def puffs(self) -> np.ndarray:
        """(K,4) array: x, y, z (NED, physical) [m] and r^2 [m^2] of every live puff."""
        st = self._store
        return np.column_stack([st.pos[:, 0], st.pos[:, 1], -np.abs(st.pos[:, 2]), st.r2])

    @property
    def puff_release_times(self) -> np.ndarray:
        """(K,) release time [s] of every live puff (same order as ``puffs``)."""
        return self._store.t_rel.copy()

    @property
    def mass_in_puffs_g(self) -> float:
        """Mass currently carried by live puffs [g]."""
        return float(self._store.mass.sum())

    @property
    def removed_mass_g(self) -> float:
        """Mass removed at the domain edge or by the puff cap [g]."""
        return self.removed_domain_mass_g + self.removed_cap_mass_g

    def _ref_speed(self, t: float) -> tuple[np.ndarray, float]:
        wk = self._wind.kernel() if hasattr(self._wind, "kernel") else None
        # The mean wind at the first source (the field's compiled sampler called directly when it has one).
        w = wind_mean(float(t), self._src0, wk) if wk is not None else np.asarray(self._wind.mean(t, self._src0), float)
        return w, max(math.hypot(w[0], w[1]), self.config.min_wind_speed_m_s)

    # ------------------------------------------------------------------ dynamics
    def step(self, t: float, dt: float) -> None:
        """Advance the puffs from ``t`` to ``t + dt`` [s] (substeps <= 1/update_rate_hz)."""
        if dt <= 0.0:
            return
        n_sub = max(1, math.ceil(dt * self.config.update_rate_hz - 1e-9))
        h = dt / n_sub
        for i in range(n_sub):
            self._substep(t + i * h, h)
        self._t = t + dt

    def _release(self, t: float, h: float) -> None:
        cfg = self.config
        runs = []
        for i, s in enumerate(cfg.sources):
            if s.rate_g_s <= 0.0:
                continue
            # Release times start_s + k/puff_rate_hz that fall in [t, t+h) and < stop_s.
            k0 = max(self._n_released[i], math.ceil((t - s.start_s) * cfg.puff_rate_hz - 1e-9))
            k1 = math.ceil((min(t + h, s.stop_s) - s.start_s) * cfg.puff_rate_hz - 1e-9)
            if k1 > k0:
                self._n_released[i] = k1
                runs.append((i, s.start_s, k0, k1))
        if not runs:
            return
        i, start, k0, k1 = runs[0]
        if len(runs) == 1 and k1 - k0 == 1:  # one puff (the usual substep): its values written as they are
            self.released_mass_g += float(self._puff_mass_g[i])
            src = self._src[i]
            self._store.append_one(src[0], src[1], -src[2], start + k0 / cfg.puff_rate_hz, self._puff_mass_g[i],
                                   cfg.source_radius_m**2, self._next_serial)  # fmt: skip
            self._next_serial += 1
            return
        new_pos, new_t, new_m = [], [], []
        for i, start, k0, k1 in runs:
            p = np.empty((k1 - k0, 3))
            p[:, :2] = self._src[i, :2]
            p[:, 2] = -self._src[i, 2]
            new_pos.append(p)
            new_t.append(start + np.arange(k0, k1) / cfg.puff_rate_hz)
            new_m.append(np.full(k1 - k0, self._puff_mass_g[i]))
        m = np.concatenate(new_m) if len(new_m) > 1 else new_m[0]
        self.released_mass_g += float(m.sum())
        # New puffs get their meander sample in this substep's refresh (see _substep).
        self._store.append(np.concatenate(new_pos) if len(new_pos) > 1 else new_pos[0],
                           np.concatenate(new_t) if len(new_t) > 1 else new_t[0], m, cfg.source_radius_m**2,
                           self._next_serial)  # fmt: skip
        self._next_serial += len(m)

    def _calibration(self, u: float, h: float) -> np.ndarray:
        """The substep's dispersion parameters at reference speed ``u`` [m/s] over ``h`` [s] (see
        :func:`sitl.world.plume.substep.puff_substep`), kept while ``u`` and ``h`` stay the same."""
        if self._cal_key != (u, h):
            cal_y = axis_calibration(self._cy, u, self._frozen_var[0])
            cal_z = axis_calibration(self._cz, u, self._frozen_var[1])
            growth = PUFF_GROWTH_SHARE * min(cal_y.small_scale_rate, cal_z.small_scale_rate)
            walk_y = math.sqrt(max(cal_y.small_scale_rate - growth, 0.0) * h)
            walk_z = math.sqrt(max(cal_z.small_scale_rate - growth, 0.0) * h)
            self._cal = np.array([cal_y.meander_sigma, cal_z.meander_sigma, walk_y, walk_z, growth,
                                  cal_y.inv_lagrangian_time, cal_z.inv_lagrangian_time])  # fmt: skip
            self._cal_key = (u, h)
        return self._cal

    def _substep(self, t: float, h: float) -> None:
        self._release(t, h)
        w_ref, u = self._ref_speed(t)
        cal = self._calibration(u, h)
        st = self._store
        k = len(st)
        wk = self._wind.kernel() if hasattr(self._wind, "kernel") else None
        if wk is None:
            self._substep_python(t, h, w_ref, cal)
        else:
            # The meander is smooth and nearly frozen in the frame the puffs ride in, so a puff's sample changes
            # slowly: each puff re-samples it every MEANDER_REFRESH_S, a 1/n_groups share of the puffs per substep,
            # by serial number (new puffs have a NaN cache and are sampled in the same pass).
            if self._phys.shape[0] < k:
                self._phys = np.zeros((2 * k, 3))
            self._normals.ensure(3 * k)
            mf = self._meander
            args = (float(t), float(h), st.pos, st.r2, st.unit, st.serial, self._n_groups,
                    self._substep_count % self._n_groups, self._phys, self._normals.nz, self._normals.nat, cal, w_ref,
                    mf.offset, mf.k, mf.phase, mf.amp, mf.omega_hat, mf.vertical, wk)  # fmt: skip
            if self._substep_fn is None:  # fixed argument types: the compiled function looked up once
                self._substep_fn = compiled_entry(puff_substep, args)
            self._substep_fn(*args)
        if k:
            if self._obstacles.heights.shape[0]:
                self._reflect(self._phys[:k])
            self._remove()
        self._substep_count += 1

    def _substep_python(self, t: float, h: float, w_ref: np.ndarray, cal: np.ndarray) -> None:
        """:func:`puff_substep` for a wind model without a compiled kernel (sampled through ``velocity``)."""
        st = self._store
        k = len(st)
        if k:
            if self._phys.shape[0] < k:
                self._phys = np.zeros((2 * k, 3))
            phys = self._phys[:k]
            physical_positions(st.pos, phys)
            vel = np.ascontiguousarray(self._wind.velocity(t, phys), dtype=float).reshape(k, 3)
            self._normals.ensure(3 * k)
            a = int(self._normals.nat[0])
            noise = self._normals.nz[a:a + 3 * k].reshape(k, 3)
            self._normals.nat[0] = a + 3 * k
            mf = self._meander
            advance_puffs(st.pos, st.r2, st.unit, st.serial, self._n_groups, self._substep_count % self._n_groups,
                          vel, noise, cal[0], cal[1], cal[2], cal[3], cal[4], h, mf.offset, mf.k, mf.phase, mf.amp)
        self._meander.advance(w_ref[:2], cal[5], cal[6], h)

    def _reflect(self, before: np.ndarray) -> None:
        """Puffs whose step ended inside a building mirrored out of it (off the wall or roof they
        crossed); they continue from there with their altitude unfolded afresh."""
        self.reflected += _reflect_puffs(self._store.pos, before, *self._obstacles)

    def _remove(self) -> None:
        st = self._store
        if self._dom_lo is not None:
            phys = np.column_stack([st.pos[:, :2], -np.abs(st.pos[:, 2])])
            inside = np.all((phys >= self._dom_lo) & (phys <= self._dom_hi), axis=1)
            if not inside.all():
                self.removed_domain_mass_g += float(st.mass[~inside].sum())
                st.keep(inside)
        excess = len(st) - self.config.max_puffs
        if excess > 0:
            # Puffs are stored in release order, so the first ones are the oldest (one: the sum is its mass).
            self.removed_cap_mass_g += float(st.mass[0] if excess == 1 else st.mass[:excess].sum())
            st.drop_oldest(excess)

    # ------------------------------------------------------------------ output
    def concentration(self, points: np.ndarray) -> np.ndarray | float:
        """Concentration [mg/m^3] at (N,3) NED points -> (N,), or (3,) -> float."""
        st = self._store
        if isinstance(points, np.ndarray) and points.shape == (3,) and points.dtype == np.float64:
            return _puff_concentration_at(points[0], points[1], points[2], st.pos, st.r2, st.mass)
        pts = np.asarray(points, dtype=float)
        single = pts.ndim == 1
        pts = np.atleast_2d(pts)
        out = _puff_concentration(np.ascontiguousarray(pts), st.pos, st.r2, st.mass)
        return float(out[0]) if single else out

    def slice_grid(
        self, z: float, x_range: tuple[float, float], y_range: tuple[float, float], n: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Horizontal slice at NED depth ``z`` [m]: returns xs (n,), ys (n,), C (n,n)
        with C[i, j] the concentration [mg/m^3] at (xs[i], ys[j], z)."""
        return concentration_slice(self.concentration, z, x_range, y_range, n)


def make_plume(
    config: PlumeConfig, wind: WindLike, seed: int | np.random.SeedSequence, t0: float = 0.0,
    obstacles: Obstacles = NO_OBSTACLES,
) -> PuffPlume | GaussianPlume:
    """Build the plume model named by ``config.model`` (ValueError if config is invalid). Buildings
    reflect the puff model's puffs; the time-averaged Gaussian model does not see them."""
    check_config(config)
    if config.model == "gaussian":
        return GaussianPlume(config, wind, seed, t0)
    return PuffPlume(config, wind, seed, t0, obstacles)
