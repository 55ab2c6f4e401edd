"""The puff plume's substep in one compiled call: the puffs' physical positions, the wind at them (the world's wind
kernel, batched), the random walk, the meander refresh and the advection (:func:`advance_puffs`), and the meander
field's frame and phases moved on; with the random-walk normals drawn ahead in blocks (:class:`NormalBlock`).

The arithmetic is that of the Python steps it replaces (``PuffPlume._substep``, ``MeanderField.advance``) in numpy's
order, so the puffs are bit for bit the same. Units m, s, m/s; NED; the puffs' vertical coordinate is the unfolded
altitude (m up).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from sitl.world.plume.meander import meander_at
from sitl.world.wind.kernel import WindKernel, _sample

#: Random-walk normals drawn ahead (about ten substeps of 1,000 puffs).
NORMALS_AHEAD = 32_768
TWO_PI = 2.0 * math.pi


@njit(cache=True)
def physical_positions(pos: np.ndarray, out: np.ndarray) -> None:
    """Physical NED positions (K, 3) m of puffs ``pos`` (x, y NED, unfolded altitude up) into ``out``."""
    for i in range(pos.shape[0]):
        out[i, 0] = pos[i, 0]
        out[i, 1] = pos[i, 1]
        out[i, 2] = -abs(pos[i, 2])


@njit(cache=True)
def advance_puffs(
    pos: np.ndarray, r2: np.ndarray, unit: np.ndarray, serial: np.ndarray, n_groups: int, group: int, vel: np.ndarray,
    noise: np.ndarray, s_xy: float, s_z: float, w_xy: float, w_z: float, growth: float, h: float, offset: np.ndarray,
    k: np.ndarray, phase: np.ndarray, amp: np.ndarray,
) -> None:  # fmt: skip
    """One puff substep of ``h`` [s], in place.

    pos (K,3): x, y NED and unfolded altitude (up) [m]; r2 (K,) [m^2]; unit (K,3): cached
    unit meander, re-sampled at the pre-step position for the puffs whose ``serial`` (K,) falls in
    ``group`` (serial mod ``n_groups``) or whose cache is NaN; vel (K,3): wind NED [m/s] at the
    physical puff positions; noise (K,3): standard normals; s_xy, s_z: meander sigma, horizontal
    and vertical [m/s]; w_xy, w_z: random-walk step standard deviation [m]; growth: r^2 growth
    rate [m^2/s]; offset/k/phase/amp: meander."""
    for i in range(pos.shape[0]):
        if serial[i] % n_groups == group or math.isnan(unit[i, 0]):
            meander_at(pos[i, 0], pos[i, 1], offset, k, phase, amp, unit[i])
        # Vertical in the unfolded coordinate: NED velocity is down, altitude is up.
        pos[i, 0] += (vel[i, 0] + unit[i, 0] * s_xy) * h + noise[i, 0] * w_xy
        pos[i, 1] += (vel[i, 1] + unit[i, 1] * s_xy) * h + noise[i, 1] * w_xy
        pos[i, 2] += (-vel[i, 2] + unit[i, 2] * s_z) * h + noise[i, 2] * w_z
        r2[i] += growth * h


@njit(cache=True)
def puff_substep(
    t: float, h: float, pos: np.ndarray, r2: np.ndarray, unit: np.ndarray, serial: np.ndarray, n_groups: int,
    group: int, phys: np.ndarray, nz: np.ndarray, nat: np.ndarray, cal: np.ndarray, w_ref: np.ndarray,
    offset: np.ndarray, k: np.ndarray, phase: np.ndarray, amp: np.ndarray, omega_hat: np.ndarray,
    vertical: np.ndarray, wk: WindKernel,
) -> None:  # fmt: skip
    """The puffs ``pos`` ... (K live) moved over ``h`` [s] from ``t`` [s]: their physical positions into ``phys``
    (the positions before the step, for the buildings' reflection), the wind at them from ``wk``, 3K normals from
    ``nz`` at ``nat[0]``, then :func:`advance_puffs`; the meander frame moved with the reference wind ``w_ref`` (3,)
    and its phases on by their rates. ``cal``: meander sigma horizontal / vertical [m/s], random-walk step
    horizontal / vertical [m], r^2 growth rate [m^2/s], inverse Lagrangian time horizontal / vertical [1/s]."""
    n = pos.shape[0]
    if n:
        ph = phys[:n]
        physical_positions(pos, ph)
        vel = _sample(t, ph, wk, False)
        a = nat[0]
        noise = nz[a:a + 3 * n].reshape(n, 3)
        nat[0] = a + 3 * n
        advance_puffs(pos, r2, unit, serial, n_groups, group, vel, noise, cal[0], cal[1], cal[2], cal[3], cal[4], h,
                      offset, k, phase, amp)  # fmt: skip
    offset[0] += w_ref[0] * h
    offset[1] += w_ref[1] * h
    for j in range(phase.shape[0]):
        rate = cal[6] if vertical[j] else cal[5]
        # np.mod: Python's float remainder (fmod, moved into [0, 2 pi)), which numba's % implements
        phase[j] = (phase[j] + omega_hat[j] * rate * h) % TWO_PI


@njit(cache=True)
def fill_normals(gen: np.random.Generator, out: np.ndarray) -> None:
    """``out`` filled with standard normals of ``gen`` in order (the values of ``gen.standard_normal(out=out)``)."""
    for i in range(out.shape[0]):
        out[i] = gen.standard_normal()


class NormalBlock:
    """A generator's standard normals drawn ahead: ``nz`` with the next unread at ``nat[0]``."""

    def __init__(self, rng: np.random.Generator, length: int = NORMALS_AHEAD) -> None:
        self.rng = rng
        self.nz = np.empty(length)
        self.nat = np.full(1, length, dtype=np.int64)

    def ensure(self, n: int) -> None:
        """At least ``n`` unread normals: the unread moved to the front, the rest drawn (the block grown if short)."""
        a = int(self.nat[0])
        if a + n <= self.nz.shape[0]:
            return
        rest = self.nz[a:].copy()
        if rest.shape[0] + n > self.nz.shape[0]:
            self.nz = np.empty(2 * (rest.shape[0] + n))
        self.nz[: rest.shape[0]] = rest
        fill_normals(self.rng, self.nz[rest.shape[0]:])
        self.nat[0] = 0
