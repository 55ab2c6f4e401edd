"""The live estimator in a worker thread, for asyncio programs (the MAVSDK mission runner).

The UKF costs tens of microseconds per IMU sample; on the event loop that keeps setpoints and the
safety checks alive it starved the loop under CPU load. :class:`EstimatorWorker` runs a
:class:`~estimator.live.LiveCore` in its own thread instead:

- :meth:`EstimatorWorker.submit` (any thread, never blocks) puts a message on a BOUNDED queue.
  IMU samples are what the filter spends its time on, so when the filter falls behind they are
  thinned first: with the queue half full only every 2nd incoming IMU sample is kept, three
  quarters full every 4th, 90 % full every 8th (``decimated_imu``; the filter runs on the thinned
  stream as on a slower IMU). When the queue is full anyway the oldest message is dropped
  (``dropped_imu``, ``dropped_other``): the queue then holds the newest stretch of the stream,
  every input type in it, and the filter bridges the gap by prediction. (Dropping the oldest IMU
  samples only would starve the filter: attitude and rotor speeds are a third of the messages.)
  Every message is either processed or counted; the order of the kept messages is preserved.
- The worker feeds the core in batches and after each batch publishes a :class:`Snapshot`
  (wind NED m/s, covariance (m/s)^2, its time on the autopilot's clock s, a ready flag, the
  status and input lines, counters). :meth:`EstimatorWorker.snapshot` returns the latest one
  (thread-safe; the snapshot is immutable).
- :meth:`EstimatorWorker.stop` ends the thread within a bounded time (queued messages are not
  drained); an exception in the core is counted (``errors``) and never ends the thread.

The numba kernels release the GIL, so the loop thread runs while the filter computes.
"""

from __future__ import annotations

import math
import threading
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimator.live import LiveConfig, LiveCore
from estimator.mavlink_decode import PREFERENCE
from estimator.ukf import WindEstimator

IMU_TYPES = frozenset(PREFERENCE["imu"])
MAX_NOTES = 100  # notes kept for the owner; older ones are dropped and counted


def warm_up(config: LiveConfig) -> None:
    """Run a throw-away filter over a few hovering samples, so that every numba kernel is compiled (or
    loaded from the cache) before the first real sample. On a fresh machine that takes 15-25 s, from
    the cache still a fraction of a second that holds the GIL: do it before an event loop starts."""
    est = WindEstimator(config.vehicle, config.estimator)
    q = np.array([1.0, 0.0, 0.0, 0.0])
    est.set_attitude(0.0, q)
    est.set_rotor_speeds(0.0, np.full(4, 393.0))
    for i in range(1, 40):
        t = 0.004 * i
        est.imu(t, np.array([0.0, 0.0, -9.81]), np.zeros(3))
        if i % 10 == 0:
            est.set_attitude(t, q)
            est.gnss_velocity(t, np.zeros(3))
            est.gnss_velocity(t + 0.001, np.zeros(2))
    est.estimate()


@dataclass(frozen=True)
class Snapshot:
    """The latest state of the worker's estimator. ``ready`` means the filter made this estimate."""

    ready: bool = False
    t: float = math.nan  # time of the estimate, autopilot clock, s
    wind_ned: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # air-mass velocity NED, m/s
    cov_ned: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))  # (m/s)^2
    vehicle_time_s: float = math.nan  # newest autopilot time seen, s
    paused: bool = False  # on the ground or landing (ground gate)
    status: str = "not started"
    inputs_line: str | None = None
    model_note: str | None = None
    withheld: str | None = None  # why the wind is withheld (the vehicle is not the model's), else None
    restarts: int = 0
    counters: dict[str, int] = field(default_factory=dict)  # core and queue counters
    accepted: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)


class EstimatorWorker:
    """A :class:`LiveCore` behind a bounded queue in a daemon thread (see the module docstring).

    Args:
        core: the live core to run (owned by the worker thread once started).
        max_queue: most messages queued; at least 10.
        batch: most messages fed between two snapshots.
        warm: compile or load the numba kernels now, in the caller's thread: loading them holds
            the GIL (tenths of a second from the cache), so do it before the event loop runs.
    """

    def __init__(self, core: LiveCore, max_queue: int = 2000, batch: int = 64, warm: bool = True) -> None:
        if max_queue < 10:
            raise ValueError(f"max_queue = {max_queue}: must be >= 10")
        if warm:
            warm_up(core.config)
        self.core = core
        self.max_queue = max_queue
        self.batch = batch
        self._imu: deque[tuple[int, Any]] = deque()
        self._other: deque[tuple[int, Any]] = deque()
        self._seq = 0
        self._imu_seen = 0  # IMU samples submitted (for the decimation)
        self._cond = threading.Condition()
        self._stop = False
        self._thread: threading.Thread | None = None
        self._snapshot = Snapshot()
        self._notes: deque[str] = deque()
        self.counts: Counter[str] = Counter()  # received, processed, decimated_imu, dropped_*, errors, high_water

    # ------------------------------------------------------------------ owner side
    def start(self) -> None:
        """Start the worker thread (once)."""
        if self._thread is not None:
            raise RuntimeError("EstimatorWorker.start: already started")
        self._thread = threading.Thread(target=self._run, name="windseek-estimator", daemon=True)
        self._thread.start()

    def submit(self, msg: Any) -> None:
        """Queue one message: IMU samples thinned when the queue fills, the oldest message dropped when
        it is full; all counted."""
        with self._cond:
            if self._stop:
                self.counts["after_stop"] += 1
                return
            self.counts["received"] += 1
            is_imu = msg.get_type() in IMU_TYPES
            if is_imu:
                fill = (len(self._imu) + len(self._other)) / self.max_queue
                keep_every = 8 if fill >= 0.9 else 4 if fill >= 0.75 else 2 if fill >= 0.5 else 1
                self._imu_seen += 1
                if self._imu_seen % keep_every:
                    self.counts["decimated_imu"] += 1
                    return
            self._seq += 1
            (self._imu if is_imu else self._other).append((self._seq, msg))
            if len(self._imu) + len(self._other) > self.max_queue:
                if self._imu and (not self._other or self._imu[0][0] < self._other[0][0]):
                    self._imu.popleft()
                    self.counts["dropped_imu"] += 1
                else:
                    self._other.popleft()
                    self.counts["dropped_other"] += 1
            n = len(self._imu) + len(self._other)
            if n > self.counts["high_water"]:
                self.counts["high_water"] = n
            self._cond.notify()

    def snapshot(self) -> Snapshot:
        """The latest published state (immutable)."""
        with self._cond:
            return self._snapshot

    def take_notes(self) -> list[str]:
        """The core's one-line events since the last call."""
        with self._cond:
            notes = list(self._notes)
            self._notes.clear()
            return notes

    def queued(self) -> int:
        with self._cond:
            return len(self._imu) + len(self._other)

    def stop(self, timeout_s: float = 2.0) -> bool:
        """Stop the thread without draining the queue; True when it ended within ``timeout_s``."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is None:
            return True
        self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def __enter__(self) -> EstimatorWorker:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ worker thread
    def _take(self) -> list[Any] | None:
        """Up to ``batch`` messages in arrival order; None when stopping. Waits at most 0.2 s."""
        with self._cond:
            if not (self._imu or self._other or self._stop):
                self._cond.wait(0.2)
            if self._stop:
                return None
            out: list[Any] = []
            imu, other = self._imu, self._other
            while (imu or other) and len(out) < self.batch:
                src = imu if imu and (not other or imu[0][0] < other[0][0]) else other
                out.append(src.popleft()[1])
            return out

    def _run(self) -> None:
        core = self.core
        while True:
            msgs = self._take()
            if msgs is None:
                return
            if not msgs:
                continue
            for m in msgs:
                try:
                    core.handle(m)
                except Exception as e:  # noqa: BLE001 - hostile input must not end the thread
                    self.counts["errors"] += 1
                    if self.counts["errors"] == 1:
                        core.note(f"estimator error (counted, the worker goes on): {type(e).__name__}: {e}")
            with self._cond:
                self.counts["processed"] += len(msgs)
            snap = self._make_snapshot()
            notes = core.take_notes()
            with self._cond:
                self._snapshot = snap
                for n in notes:
                    if len(self._notes) >= MAX_NOTES:
                        self._notes.popleft()
                        self.counts["notes_dropped"] += 1
                    self._notes.append(n)

    def _make_snapshot(self) -> Snapshot:
        core = self.core
        out = core.output()
        e = core.est
        with self._cond:
            counts = dict(self.counts)
        return Snapshot(
            ready=out is not None,
            t=out.t if out is not None else math.nan,
            wind_ned=out.wind_ned if out is not None else np.full(3, np.nan),
            cov_ned=out.cov_ned if out is not None else np.full((3, 3), np.nan),
            vehicle_time_s=core.t,
            paused=core.paused(),
            status=core.status_line(),
            inputs_line=core.select.inputs_line() if core.select.selected else None,
            model_note=core.model_note,
            withheld=core.fit.mismatch,
            restarts=core.restarts,
            counters={**dict(core.counters), **counts},
            accepted=dict(e.accepted),
            rejected=dict(e.rejected),
        )
