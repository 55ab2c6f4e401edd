"""The link-fault model: pure, seeded, deterministic; no sockets, no clock of its own.

A :class:`Channel` is one direction of a link. Every unit (a UDP datagram, or one MAVLink frame)
offered to it at time ``now`` (seconds, any monotonic origin) goes through, in this order:

1. **cut**: while the link is cut every unit is dropped (``dropped_cut``), and a cut drops what
   was in flight too (a real link loses what it was carrying); **filter**: a unit that holds a frame
   whose message id is in ``drop_ids`` is dropped (``dropped_filter``; with datagram units the whole
   datagram goes, so filter with frame units);
2. **loss**: Bernoulli with probability ``loss``, or a Gilbert-Elliott burst model (``burst``):
   a two-state chain, good -> bad with probability ``p_enter`` per unit, bad -> good with
   ``p_leave``; in the bad state a unit is lost with ``burst_loss``, in the good state with
   ``loss`` (``dropped_loss``);
3. **duplication**: with probability ``duplicate`` a second copy follows the first
   (``duplicated``); both go on through the steps below;
4. **bandwidth**: the link serialises ``bandwidth_bps`` bytes per second; a unit waits for the
   units ahead of it, and one that would make the backlog exceed ``queue_bytes`` is dropped
   (``dropped_queue``: drop-tail, like a radio's full buffer);
5. **latency and jitter**: delivered ``latency_s`` + U(-``jitter_s``, +``jitter_s``) (at least 0)
   after it left the bandwidth queue, but never before a unit offered earlier: jitter bunches
   units, it does not reorder them (``delayed`` counts units not delivered at once);
6. **reordering**: with probability ``reorder`` a unit is held back and delivered just after the
   next one (``reordered``); if no next unit comes within ``max_hold_s``, it goes alone.

Every unit draws the same five uniform numbers from the channel's ``numpy`` Generator whatever
happens to it, so the same seed and the same sequence of units give the same faults, unit for
unit, independently of timing. Everything is bounded: at most ``max_units`` units and
``max_bytes`` bytes in flight (``dropped_overflow`` beyond).
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from wire.proxy.framing import message_ids

#: Counter names of a channel, in report order.
COUNTERS = ("rx_units", "rx_bytes", "tx_units", "tx_bytes", "dropped_loss", "dropped_cut", "dropped_filter",
            "dropped_queue", "dropped_overflow", "dropped_no_peer", "duplicated", "reordered", "delayed")  # fmt: skip


@dataclass(frozen=True)
class Faults:
    """The faults of one direction (probabilities in [0, 1], times in s, sizes in bytes).

    loss: loss probability (in the good state when ``burst`` is set).
    burst: Gilbert-Elliott ``(p_enter, p_leave)`` per unit, or None (independent losses).
    burst_loss: loss probability in the bad state.
    duplicate, reorder: probabilities per unit.
    latency_s, jitter_s: one-way delay and its spread (uniform, +-jitter_s).
    bandwidth_bps: bytes per second (inf: unlimited); queue_bytes: backlog limit (0: 1 s of bandwidth,
        at least 4 kB).
    max_hold_s: the longest a reordered unit waits for the next one.
    drop_ids: MAVLink message ids that never get through (e.g. ``{0}``: every HEARTBEAT).
    """

    loss: float = 0.0
    burst: tuple[float, float] | None = None
    burst_loss: float = 1.0
    duplicate: float = 0.0
    reorder: float = 0.0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    bandwidth_bps: float = math.inf
    queue_bytes: int = 0
    max_hold_s: float = 0.2
    drop_ids: frozenset[int] = frozenset()

    def validate(self) -> Faults:
        """Self, or ValueError naming the bad field."""
        probs = {"loss": self.loss, "burst_loss": self.burst_loss, "duplicate": self.duplicate,
                 "reorder": self.reorder}  # fmt: skip
        if self.burst is not None:
            probs.update({"burst p_enter": self.burst[0], "burst p_leave": self.burst[1]})
        for name, p in probs.items():
            if not (math.isfinite(p) and 0.0 <= p <= 1.0):
                raise ValueError(f"{name} {p}: must be a probability in [0, 1]")
        for name, v in (("latency", self.latency_s), ("jitter", self.jitter_s), ("max hold", self.max_hold_s)):
            if not (math.isfinite(v) and 0.0 <= v <= 60.0):
                raise ValueError(f"{name} {v} s: must be in [0, 60] s")
        if not (self.bandwidth_bps > 0.0) or math.isnan(self.bandwidth_bps):
            raise ValueError(f"bandwidth {self.bandwidth_bps} B/s: must be > 0")
        if self.queue_bytes < 0:
            raise ValueError(f"queue {self.queue_bytes} B: must be >= 0")
        if any(not 0 <= i < 1 << 24 for i in self.drop_ids):
            raise ValueError(f"message ids {sorted(self.drop_ids)}: must be in [0, 2^24)")
        return self

    def queue_limit(self) -> float:
        """The bandwidth queue's backlog limit in bytes."""
        if self.queue_bytes > 0:
            return float(self.queue_bytes)
        return max(4096.0, self.bandwidth_bps) if math.isfinite(self.bandwidth_bps) else math.inf

    def describe(self) -> str:
        """One line, only the faults that are on."""
        parts = []
        if self.burst is not None:
            parts.append(f"burst loss (enter {self.burst[0]:g}, leave {self.burst[1]:g}, bad {self.burst_loss:g}, "
                         f"good {self.loss:g})")  # fmt: skip
        elif self.loss:
            parts.append(f"loss {self.loss:g}")
        if self.duplicate:
            parts.append(f"dup {self.duplicate:g}")
        if self.reorder:
            parts.append(f"reorder {self.reorder:g}")
        if self.latency_s or self.jitter_s:
            parts.append(f"latency {self.latency_s * 1e3:g}+-{self.jitter_s * 1e3:g} ms")
        if math.isfinite(self.bandwidth_bps):
            parts.append(f"bandwidth {self.bandwidth_bps:g} B/s (queue {self.queue_limit():g} B)")
        if self.drop_ids:
            parts.append(f"drop message ids {','.join(map(str, sorted(self.drop_ids)))}")
        return ", ".join(parts) or "no faults"


class Channel:
    """One direction of a link (see the module docstring). ``offer`` units, take them back with ``due``.

    Counters (:data:`COUNTERS`) are in :attr:`counters`; ``dropped_no_peer`` is counted by the I/O
    layer (a unit due with nobody to send it to).
    """

    def __init__(self, faults: Faults, rng: np.random.Generator, max_units: int = 20000,
                 max_bytes: int = 8 << 20) -> None:  # fmt: skip
        self.f = faults.validate()
        self.rng = rng
        self.max_units, self.max_bytes = max_units, max_bytes
        self.counters: Counter[str] = Counter({k: 0 for k in COUNTERS})
        self.bad = False  # Gilbert-Elliott state
        self._busy_until = -math.inf  # the bandwidth queue is transmitting until then
        self._last_release = -math.inf
        self._queue: deque[tuple[float, bytes]] = deque()  # (release time, unit), release non-decreasing
        self._bytes = 0
        self._held: tuple[bytes, float] | None = None  # a reordered unit and its deadline

    @property
    def in_flight(self) -> int:
        return len(self._queue) + (self._held is not None)

    def offer(self, now: float, unit: bytes, cut: bool = False) -> None:
        """A unit arrives at ``now`` (s); ``cut``: the link is cut now."""
        c, f = self.counters, self.f
        c["rx_units"] += 1
        c["rx_bytes"] += len(unit)
        u_loss, u_state, u_dup, u_reorder, u_jitter = self.rng.random(5)  # always five: see the docstring
        if cut:
            c["dropped_cut"] += 1
            return
        if f.drop_ids and not f.drop_ids.isdisjoint(message_ids(unit)):
            c["dropped_filter"] += 1
            return
        if f.burst is not None:
            self.bad = (u_state >= f.burst[1]) if self.bad else (u_state < f.burst[0])
        if u_loss < (f.burst_loss if self.bad else f.loss):
            c["dropped_loss"] += 1
            return
        copies = 2 if u_dup < f.duplicate else 1
        if copies == 2:
            c["duplicated"] += 1
        for i in range(copies):  # only the last copy may be held back (twins swapped would look in order)
            self._schedule(now, unit, i == copies - 1 and u_reorder < f.reorder, u_jitter)

    def _schedule(self, now: float, unit: bytes, hold: bool, u_jitter: float) -> None:
        c, f = self.counters, self.f
        n = len(unit)
        if len(self._queue) >= self.max_units or self._bytes + n > self.max_bytes:
            c["dropped_overflow"] += 1
            return
        ready = now
        if math.isfinite(f.bandwidth_bps):
            backlog = max(0.0, self._busy_until - now) * f.bandwidth_bps
            if backlog + n > f.queue_limit():
                c["dropped_queue"] += 1
                return
            self._busy_until = max(now, self._busy_until) + n / f.bandwidth_bps
            ready = self._busy_until
        delay = f.latency_s + (2.0 * u_jitter - 1.0) * f.jitter_s
        release = max(ready + max(delay, 0.0), self._last_release)
        if release > now + 1e-9:
            c["delayed"] += 1
        if self._held is None and hold:
            self._held = (unit, release + f.max_hold_s)
            self._last_release = release
            return
        self._push(release, unit)
        if self._held is not None:  # the held unit goes right after this one
            self._push(release, self._held[0])
            self._held = None
            c["reordered"] += 1

    def _push(self, release: float, unit: bytes) -> None:
        self._queue.append((release, unit))
        self._bytes += len(unit)
        self._last_release = max(self._last_release, release)

    def due(self, now: float) -> list[bytes]:
        """The units to deliver at ``now``, in delivery order."""
        if self._held is not None and self._held[1] <= now:  # nothing came to overtake it
            self._push(max(self._held[1], self._last_release), self._held[0])
            self._held = None
        out = []
        q = self._queue
        while q and q[0][0] <= now:
            _, unit = q.popleft()
            self._bytes -= len(unit)
            out.append(unit)
        return out

    def next_time(self) -> float:
        """When :meth:`due` next has something (inf: nothing in flight)."""
        t = self._queue[0][0] if self._queue else math.inf
        return min(t, self._held[1]) if self._held is not None else t

    def drop_all(self) -> int:
        """A cut began: what is in flight is lost (counted as ``dropped_cut``); returns how many."""
        n = self.in_flight
        self._queue.clear()
        self._bytes = 0
        self._held = None
        self._busy_until = -math.inf
        self.counters["dropped_cut"] += n
        return n

    def sent(self, unit: bytes) -> None:
        """The I/O layer delivered ``unit``."""
        self.counters["tx_units"] += 1
        self.counters["tx_bytes"] += len(unit)


@dataclass(frozen=True)
class Cut:
    """A scheduled cut: from ``start_s`` for ``duration_s`` (inf: permanent), seconds after the trigger."""

    start_s: float
    duration_s: float = math.inf

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    @staticmethod
    def parse(text: str) -> Cut:
        """``START:DURATION`` or ``START:`` (permanent), seconds; ValueError (one line) otherwise."""
        start, sep, dur = text.partition(":")
        try:
            s = float(start)
            d = float(dur) if dur.strip() else math.inf
        except ValueError:
            s = d = math.nan
        if not sep or not (math.isfinite(s) and s >= 0.0) or not (d > 0.0):
            raise ValueError(f"cut {text!r}: expected START:DURATION or START: (permanent), seconds, "
                             "START >= 0, DURATION > 0")  # fmt: skip
        return Cut(s, d)


class CutSchedule:
    """Scheduled cuts (relative to a trigger time) plus a manual cut; tells whether the link is cut."""

    def __init__(self, cuts: list[Cut] | tuple[Cut, ...] = ()) -> None:
        self.cuts = sorted(cuts, key=lambda c: c.start_s)
        self.t0: float | None = None  # trigger time; None: not triggered yet (no scheduled cut applies)
        self.manual = False

    def trigger(self, now: float) -> None:
        if self.t0 is None:
            self.t0 = now

    def active(self, now: float) -> bool:
        if self.manual:
            return True
        if self.t0 is None:
            return False
        dt = now - self.t0
        return any(c.start_s <= dt < c.end_s for c in self.cuts)

    def next_change(self, now: float) -> float:
        """The next time a scheduled cut begins or ends (inf: none)."""
        if self.t0 is None:
            return math.inf
        times = [self.t0 + t for c in self.cuts for t in (c.start_s, c.end_s) if self.t0 + t > now]
        return min(times, default=math.inf)
