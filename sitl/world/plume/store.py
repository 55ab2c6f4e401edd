"""The puff plume's live puffs, in release order, in arrays with room to grow.

A puff plume releases a few puffs and drops as many of the oldest (the puff cap) at every update,
at 10 Hz or more: copying every puff array to append one puff (``np.concatenate``, six arrays per
update) cost more than moving the puffs. :class:`PuffStore` keeps each quantity in a buffer with
spare rows after the live ones: a release writes into the spare rows, dropping the oldest moves the
start, and the live puffs are moved to the front only when the spare rows run out (about once per
``capacity - live`` releases). The live puffs are views (:attr:`PuffStore.pos` ...) in release
order, the same values in the same order as the concatenated arrays they replace.

Units: positions m (x, y NED and the unfolded altitude, m up), r^2 m^2, mass g, times s.
"""

from __future__ import annotations

import numpy as np

#: Spare rows a buffer is given beyond its live puffs when it grows (at least this many, or as many as live).
MIN_SPARE = 64


class PuffStore:
    """Live puff state: ``pos`` (K, 3), ``r2`` (K,), ``mass`` (K,), ``t_rel`` (K,) release times,
    ``serial`` (K,) int64 release serial numbers, ``unit`` (K, 3) cached unit meander (NaN: not
    sampled yet). The attributes are views of the live rows; they change after every call that adds
    or removes puffs, so callers read them afresh."""

    def __init__(self) -> None:
        self._lo = self._hi = 0
        self._bufs = _buffers(0)
        self._views()

    def __len__(self) -> int:
        return self._hi - self._lo

    def _views(self) -> None:
        lo, hi = self._lo, self._hi
        b = self._bufs
        self.pos, self.r2, self.mass = b["pos"][lo:hi], b["r2"][lo:hi], b["mass"][lo:hi]
        self.t_rel, self.serial, self.unit = b["t_rel"][lo:hi], b["serial"][lo:hi], b["unit"][lo:hi]

    def _room(self, n: int) -> None:
        """At least ``n`` spare rows after the live ones: the live rows moved to the front, the
        buffers grown if that is not enough."""
        live = len(self)
        cap = self._bufs["r2"].shape[0]
        if self._hi + n <= cap:
            return
        bufs = _buffers(live + n + max(MIN_SPARE, live + n)) if live + n > cap else self._bufs
        for name, buf in self._bufs.items():
            bufs[name][:live] = buf[self._lo:self._hi]  # numpy copies overlapping ranges correctly
        self._bufs, self._lo, self._hi = bufs, 0, live

    def append(self, pos: np.ndarray, t_rel: np.ndarray, mass: np.ndarray, r2: float, serial0: int) -> None:
        """Add ``len(mass)`` new puffs after the live ones: positions ``pos`` (n, 3), release times
        ``t_rel`` (n,) s, masses ``mass`` (n,) g, variance ``r2`` m^2 each, serials from ``serial0``;
        their meander not sampled yet."""
        n = mass.shape[0]
        self._room(n)
        a, b = self._hi, self._hi + n
        bufs = self._bufs
        bufs["pos"][a:b] = pos
        bufs["t_rel"][a:b] = t_rel
        bufs["mass"][a:b] = mass
        bufs["r2"][a:b] = r2
        bufs["serial"][a:b] = np.arange(serial0, serial0 + n)
        bufs["unit"][a:b] = np.nan
        self._hi = b
        self._views()

    def append_one(self, x: float, y: float, alt: float, t_rel: float, mass: float, r2: float, serial: int) -> None:
        """Add one puff (see :meth:`append`): position x, y NED and unfolded altitude [m], release time [s],
        mass [g], variance [m^2], serial."""
        self._room(1)
        a = self._hi
        bufs = self._bufs
        p = bufs["pos"][a]
        p[0], p[1], p[2] = x, y, alt
        bufs["t_rel"][a] = t_rel
        bufs["mass"][a] = mass
        bufs["r2"][a] = r2
        bufs["serial"][a] = serial
        bufs["unit"][a] = np.nan
        self._hi = a + 1
        self._views()

    def drop_oldest(self, n: int) -> None:
        """Remove the ``n`` oldest puffs (the first ``n``: they are stored in release order)."""
        self._lo += min(n, len(self))
        self._views()

    def keep(self, mask: np.ndarray) -> None:
        """Keep the puffs where ``mask`` (K,) bool is True, in their order."""
        live = int(np.count_nonzero(mask))
        lo = self._lo
        for buf in self._bufs.values():
            buf[lo:lo + live] = buf[lo:self._hi][mask]
        self._hi = lo + live
        self._views()


def _buffers(cap: int) -> dict[str, np.ndarray]:
    """Empty buffers for ``cap`` puffs (see :class:`PuffStore`)."""
    return {"pos": np.zeros((cap, 3)), "r2": np.zeros(cap), "mass": np.zeros(cap), "t_rel": np.zeros(cap),
            "serial": np.zeros(cap, dtype=np.int64), "unit": np.zeros((cap, 3))}  # fmt: skip
