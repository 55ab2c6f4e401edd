"""The link proxy: two endpoints, a seeded fault model per direction, one I/O thread.

``a -> b`` and ``b -> a`` each have a :class:`~wire.proxy.faults.Channel`; the thread reads what
arrives, offers it to the channel of its direction, and sends what the channels release, in time.
Cuts (scheduled ``--cut START:DURATION`` windows, or :meth:`LinkProxy.cut` / :meth:`LinkProxy.restore`)
stop both directions. Scheduled cuts count from the *trigger*: the proxy's start, the first unit
from either side, or the first HEARTBEAT of an armed autopilot (``armed``: units are decoded with
the project dialect until then, and no longer).

Use::

    with LinkProxy("udpin:127.0.0.1:0", "udpout:127.0.0.1:14540", Faults(loss=0.3), seed=1) as px:
        port = px.a.port          # point the autopilot here
        ...
        px.cut(); ...; px.restore()
        report = px.report()      # counters per direction, cuts, trigger

Times are monotonic wall-clock seconds from :meth:`LinkProxy.start`. Every wait is bounded (the
select timeout is at most :data:`TICK_S`), every buffer too (see :mod:`wire.proxy.faults` and
:mod:`wire.proxy.endpoints`).
"""

from __future__ import annotations

import contextlib
import math
import select
import threading
import time
from typing import Any

import numpy as np

from wire.proxy.endpoints import Endpoint, EndpointSpec, open_endpoint
from wire.proxy.faults import Channel, Cut, CutSchedule, Faults

TICK_S = 0.05
TRIGGERS = ("start", "first-packet", "armed")
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_AUTOPILOT_INVALID = 8


class LinkProxy:
    """A faulty link between endpoints ``a`` and ``b`` (spec strings, see :mod:`wire.proxy.endpoints`).

    ab / ba: the faults of each direction (``ba`` defaults to ``ab``); cuts: scheduled cuts; seed:
    seeds both directions' generators (independent streams); trigger: one of :data:`TRIGGERS`;
    frames: UDP units are MAVLink frames instead of datagrams.
    """

    def __init__(self, a: str, b: str, ab: Faults | None = None, ba: Faults | None = None,
                 cuts: list[Cut] | tuple[Cut, ...] = (), seed: int = 0, trigger: str = "start",
                 frames: bool = False) -> None:  # fmt: skip
        if trigger not in TRIGGERS:
            raise ValueError(f"trigger {trigger!r}: choose one of {', '.join(TRIGGERS)}")
        self.specs = (EndpointSpec.parse(a), EndpointSpec.parse(b))
        ab = (ab or Faults()).validate()
        ba = (ba if ba is not None else ab).validate()
        self.faults = {"a->b": ab, "b->a": ba}
        self.seed = int(seed)
        rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(self.seed).spawn(2)]
        self.channels = {"a->b": Channel(ab, rngs[0]), "b->a": Channel(ba, rngs[1])}
        self.schedule = CutSchedule(cuts)
        self.trigger_kind = trigger
        self.frames = frames
        self.a: Endpoint
        self.b: Endpoint
        self._opened = False
        self.names = (str(self.specs[0]), str(self.specs[1]))  # with the bound ports once open
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = math.nan
        self._cut_now = False
        self._cut_log: list[dict[str, Any]] = []  # {"start_s", "end_s"} as applied
        self._parser: Any = None
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ life cycle
    def open(self) -> LinkProxy:
        """Bind / listen both ends (their ports are known after this); OSError if one cannot."""
        if not self._opened:
            self.a = open_endpoint(self.specs[0], self.frames)
            try:
                self.b = open_endpoint(self.specs[1], self.frames)
            except BaseException:
                self.a.close()
                raise
            self._opened = True
            self.names = (self.a.describe(), self.b.describe())
        return self

    def start(self) -> LinkProxy:
        """Open the ends and forward in a background thread until :meth:`stop`."""
        self.open()
        self._t0 = time.monotonic()
        if self.trigger_kind == "start":
            self.schedule.trigger(0.0)
        elif self.trigger_kind == "armed":
            from wire.dialect import mavlink as mav

            self._parser = mav.MAVLink(None)
            self._parser.robust_parsing = True
        self._thread = threading.Thread(target=self._serve, name="link-proxy", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop forwarding and close the ends (what is still in flight is not delivered)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
        if self._opened:
            self.a.close()
            self.b.close()
            self._opened = False

    def __enter__(self) -> LinkProxy:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def now(self) -> float:
        """Seconds since :meth:`start`."""
        return time.monotonic() - self._t0

    # ------------------------------------------------------------------ control (any thread)
    def cut(self) -> None:
        """Cut the link now, both ways, until :meth:`restore` (what is in flight is lost)."""
        with self._lock:
            self.schedule.manual = True
            self._update_cut(self.now())

    def restore(self) -> None:
        """End a :meth:`cut` (scheduled cuts keep their windows)."""
        with self._lock:
            self.schedule.manual = False
            self._update_cut(self.now())

    def set_faults(self, direction: str, faults: Faults) -> None:
        """Change the faults of ``"a->b"`` or ``"b->a"`` from now on (units in flight keep their fate)."""
        if direction not in self.channels:
            raise ValueError(f"direction {direction!r}: 'a->b' or 'b->a'")
        faults.validate()
        with self._lock:
            self.faults[direction] = faults
            self.channels[direction].f = faults

    def is_cut(self) -> bool:
        return self._cut_now

    def report(self) -> dict[str, Any]:
        """Counters per direction, the ends' counters, the cuts as applied, the trigger; JSON-ready."""
        with self._lock:
            now = self.now() if math.isfinite(self._t0) else 0.0
            out: dict[str, Any] = {
                "elapsed_s": round(now, 3), "seed": self.seed,
                "a": self.names[0], "b": self.names[1],
                "unit": "frame" if self.frames else "datagram (UDP) / frame (TCP)",
                "faults": {d: f.describe() for d, f in self.faults.items()},
                "trigger": self.trigger_kind,
                "triggered_at_s": None if self.schedule.t0 is None else round(self.schedule.t0, 3),
                "cut_now": self._cut_now,
                "cuts": [dict(c) for c in self._cut_log],
            }  # fmt: skip
            for d, ch in self.channels.items():
                out[d] = dict(ch.counters) | {"in_flight": ch.in_flight}
            if self._opened:
                out["a_end"], out["b_end"] = dict(self.a.counters), dict(self.b.counters)
        return out

    # ------------------------------------------------------------------ the thread
    def _serve(self) -> None:
        try:
            while not self._stop.is_set():
                self._step()
        except BaseException as e:  # keep the reason: a silent dead proxy looks like a cut link
            self.error = e
            raise

    def _step(self) -> None:
        ends = {"a->b": (self.a, self.b), "b->a": (self.b, self.a)}
        with self._lock:
            now = self.now()
            self._update_cut(now)
            wake = min([ch.next_time() for ch in self.channels.values()] + [self.schedule.next_change(now)])
        rfds = {fd: "a->b" for fd in self.a.rfds()} | {fd: "b->a" for fd in self.b.rfds()}
        wfds = {fd: self.a for fd in self.a.wfds()} | {fd: self.b for fd in self.b.wfds()}
        timeout = min(TICK_S, max(0.0, wake - now))
        try:
            r, w, _ = select.select(list(rfds), list(wfds), [], timeout)
        except (OSError, ValueError):  # an fd closed under us (a TCP peer went): look again
            r, w = [], []
        for fd in w:
            wfds[fd].writable(fd)
        with self._lock:
            now = self.now()
            for fd in r:
                d = rfds[fd]
                for unit in ends[d][0].read(fd):
                    self._arrived(now, unit)
                    self.channels[d].offer(now, unit, self._cut_now)
            self._update_cut(now)
            for d, ch in self.channels.items():
                for unit in ch.due(now):
                    if ends[d][1].send(unit):
                        ch.sent(unit)
                    else:
                        ch.counters["dropped_no_peer"] += 1
            mono = time.monotonic()
            self.a.tick(mono)
            self.b.tick(mono)

    def _arrived(self, now: float, unit: bytes) -> None:
        """Watch for the trigger (before it fired)."""
        if self.schedule.t0 is not None:
            return
        if self.trigger_kind == "first-packet":
            self.schedule.trigger(now)
            return
        with contextlib.suppress(Exception):  # anything the parser chokes on is simply not the trigger
            for m in self._parser.parse_buffer(bytes(unit)) or []:
                if (m.get_type() == "HEARTBEAT" and m.autopilot != MAV_AUTOPILOT_INVALID
                        and m.base_mode & MAV_MODE_FLAG_SAFETY_ARMED):  # fmt: skip
                    self.schedule.trigger(now)
                    self._parser = None
                    return

    def _update_cut(self, now: float) -> None:
        """Apply a change of the cut state (lock held): at a cut's start what is in flight is lost."""
        cut = self.schedule.active(now)
        if cut == self._cut_now:
            return
        self._cut_now = cut
        if cut:
            for ch in self.channels.values():
                ch.drop_all()
            self._cut_log.append({"start_s": round(now, 3), "end_s": None, "manual": self.schedule.manual})
        elif self._cut_log:
            self._cut_log[-1]["end_s"] = round(now, 3)
