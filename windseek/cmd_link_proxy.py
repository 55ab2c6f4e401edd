"""``windseek link-proxy A B``: a faulty MAVLink link between two endpoints, for testing missions under bad links.

Sits between an autopilot (or ``windseek sitl``) and a ground station, MAVSDK or a companion program
and forwards both ways with seeded faults (:mod:`wire.proxy`): loss (independent or Gilbert-Elliott
bursts), duplication, reordering, latency and jitter, a bandwidth limit with a bounded queue,
scheduled cuts, and messages filtered out by id. A fault option takes one value for both directions
or ``AB/BA`` (a->b, then b->a). Counters are shown while it runs (a live table on a terminal, a line
every 10 s otherwise) and printed at the end (``--json``: one JSON object on stdout). SIGINT /
SIGTERM stop it cleanly; SIGUSR1 cuts the link both ways until SIGUSR2 (``kill -USR1 PID``: a cut
by hand, on top of the ``--cut`` schedule).

Example: the SITL sends to the proxy's port 14600, the proxy passes on to MAVSDK on 14540::

    windseek sitl open-field --udp 127.0.0.1:14600 --udp-bind 127.0.0.1:14601
    windseek link-proxy udpin:127.0.0.1:14600 udpout:127.0.0.1:14540 --loss 0.3 --cut 40:15 --trigger armed
    windseek mission --connect udpin://127.0.0.1:14540 --strategy surge-cast
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from wire.jsonsafe import json_safe
from wire.proxy import TRIGGERS, Cut, Faults, LinkProxy
from wire.proxy.endpoints import EndpointSpec


def _pair(convert: Callable[[str], float], what: str) -> Callable[[str], tuple[float, float]]:
    """An argparse type: ``V`` (both directions) or ``AB/BA``, each converted and checked."""

    def parse(text: str) -> tuple[float, float]:
        parts = text.split("/")
        if len(parts) not in (1, 2):
            raise argparse.ArgumentTypeError(f"{text!r}: expected one {what} or two as A->B/B->A")
        try:
            vals = [convert(p) for p in parts]
        except ValueError as e:
            raise argparse.ArgumentTypeError(f"{text!r}: {e}") from None
        return (vals[0], vals[-1])

    return parse


def _number(lo: float, hi: float, unit: str) -> Callable[[str], float]:
    def conv(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise ValueError(f"{text!r} is not a number") from None
        if not (lo <= v <= hi):
            raise ValueError(f"{text} must be in [{lo:g}, {hi:g}]{unit}")
        return v

    return conv


def _bursts(text: str) -> tuple[tuple[float, float], tuple[float, float]]:
    """``ENTER:LEAVE`` or ``ENTER:LEAVE/ENTER:LEAVE`` (Gilbert-Elliott transition probabilities)."""
    out = []
    for part in text.split("/"):
        enter, sep, leave = part.partition(":")
        try:
            pe, pl = float(enter), float(leave)
        except ValueError:
            pe = pl = math.nan
        if not sep or not (0.0 < pe <= 1.0 and 0.0 < pl <= 1.0):
            raise argparse.ArgumentTypeError(f"{text!r}: expected ENTER:LEAVE probabilities in (0, 1] "
                                             "(or two as A->B/B->A)")  # fmt: skip
        out.append((pe, pl))
    if len(out) > 2:
        raise argparse.ArgumentTypeError(f"{text!r}: at most two ENTER:LEAVE pairs (A->B/B->A)")
    return out[0], out[-1]


def _drop_ids(text: str) -> tuple[frozenset[int], frozenset[int]]:
    """``NAME_OR_ID[,...]`` (both directions) or ``LIST/LIST`` (a->b, b->a; either may be empty)."""
    from wire.dialect import mavlink as mav

    parts = text.split("/")
    if len(parts) > 2:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a list of messages or two as A->B/B->A")
    out = []
    for part in parts:
        ids = set()
        for name in filter(None, (x.strip() for x in part.split(","))):
            mid = int(name) if name.isdigit() else getattr(mav, f"MAVLINK_MSG_ID_{name.upper()}", None)
            if mid is None:
                raise argparse.ArgumentTypeError(f"{name!r}: not a MAVLink message name or id (e.g. HEARTBEAT, 0)")
            ids.add(int(mid))
        out.append(frozenset(ids))
    return out[0], out[-1]


def _endpoint(text: str) -> str:
    try:
        EndpointSpec.parse(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def _cut(text: str) -> Cut:
    try:
        return Cut.parse(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "link-proxy",
        help="a faulty MAVLink link between two endpoints (seeded loss, duplicates, reordering, latency, cuts)",
        description="Forward MAVLink between endpoints A and B with seeded faults; fault values are one value "
        "for both directions or A->B/B->A. Endpoints: udpin:HOST:PORT (listen), udpout:HOST:PORT (send first), "
        "tcpin:HOST:PORT (accept), tcpout:HOST:PORT (connect).",
    )
    prob = _number(0.0, 1.0, "")
    p.add_argument("a", metavar="A", type=_endpoint,
                   help="one end, e.g. udpin:127.0.0.1:14600 (where the autopilot sends)")
    p.add_argument("b", metavar="B", type=_endpoint,
                   help="the other end, e.g. udpout:127.0.0.1:14540 (MAVSDK's udpin port)")
    p.add_argument("--loss", type=_pair(prob, "probability"), default=(0.0, 0.0), metavar="P[/P]",
                   help="loss probability per unit (in the good state with --burst)")
    p.add_argument("--burst", type=_bursts, default=None, metavar="ENTER:LEAVE[/ENTER:LEAVE]",
                   help="Gilbert-Elliott burst losses: probabilities per unit to enter and to leave the bad state")
    p.add_argument("--burst-loss", type=_pair(prob, "probability"), default=(1.0, 1.0), metavar="P[/P]",
                   help="loss probability in the bad state (default 1)")
    p.add_argument("--dup", type=_pair(prob, "probability"), default=(0.0, 0.0), metavar="P[/P]",
                   help="duplication probability per unit")
    p.add_argument("--reorder", type=_pair(prob, "probability"), default=(0.0, 0.0), metavar="P[/P]",
                   help="probability that a unit is held back and delivered after the next one")
    ms = _number(0.0, 60000.0, " ms")
    p.add_argument("--latency", type=_pair(ms, "delay"), default=(0.0, 0.0), metavar="MS[/MS]",
                   help="one-way delay, ms")
    p.add_argument("--jitter", type=_pair(ms, "delay"), default=(0.0, 0.0), metavar="MS[/MS]",
                   help="delay spread, +-ms, uniform (it bunches units, never reorders them)")
    p.add_argument("--bandwidth", type=_pair(_number(1.0, 1e12, " B/s"), "rate"), default=None, metavar="BPS[/BPS]",
                   help="bytes per second (a 57600 baud radio carries about 5760 B/s); default unlimited")
    p.add_argument("--queue", type=_pair(_number(1.0, 1e9, " B"), "size"), default=None, metavar="BYTES[/BYTES]",
                   help="bandwidth queue limit, bytes (default: 1 s of bandwidth, at least 4096); drop-tail")
    p.add_argument("--drop-msg", type=_drop_ids, default=(frozenset(), frozenset()), metavar="MSGS[/MSGS]",
                   help="messages that never get through, by name or id (e.g. HEARTBEAT; HEARTBEAT/ = a->b only); "
                   "use with --frames on UDP (a datagram holding one goes whole)")
    p.add_argument("--cut", type=_cut, action="append", default=[], metavar="START:DURATION",
                   help="cut both ways from START for DURATION seconds after the trigger; START: alone = for good "
                   "(repeatable)")
    p.add_argument("--trigger", choices=TRIGGERS, default="start",
                   help="when the --cut clock starts: the proxy's start (default), the first unit, or the first "
                   "HEARTBEAT of an armed autopilot")
    p.add_argument("--frames", action="store_true",
                   help="UDP: fault single MAVLink frames instead of whole datagrams (like a radio); TCP always does")
    p.add_argument("--seed", type=int, default=0, help="seed of the fault generators (default 0)")
    p.add_argument("--duration", type=_number(0.001, 1e9, " s"), default=None, metavar="S",
                   help="stop after S seconds")
    p.add_argument("--json", action="store_true", help="print the final counters as one JSON object on stdout")
    p.add_argument("--progress-every", type=_number(0.0, 3600.0, " s"), default=None, metavar="S",
                   help="seconds between progress updates on stderr (default: live on a terminal, 10 s otherwise; "
                   "0 = none)")
    p.set_defaults(func=run)


def faults_from_args(args: argparse.Namespace) -> tuple[Faults, Faults]:
    """The a->b and b->a :class:`Faults` of the parsed options (ValueError on a bad combination)."""
    out = []
    for i in (0, 1):
        out.append(Faults(
            loss=args.loss[i], burst=None if args.burst is None else args.burst[i], burst_loss=args.burst_loss[i],
            duplicate=args.dup[i], reorder=args.reorder[i], latency_s=args.latency[i] / 1e3,
            jitter_s=args.jitter[i] / 1e3, bandwidth_bps=math.inf if args.bandwidth is None else args.bandwidth[i],
            queue_bytes=0 if args.queue is None else int(args.queue[i]),
            drop_ids=args.drop_msg[i]).validate())  # fmt: skip
    return out[0], out[1]


def line(rep: dict[str, Any]) -> str:
    """One progress line from :meth:`LinkProxy.report`."""
    parts = [f"t {rep['elapsed_s']:7.1f} s" + ("  CUT" if rep["cut_now"] else "")]
    for d in ("a->b", "b->a"):
        c = rep[d]
        parts.append(f"{d} {c['tx_units']} of {c['rx_units']} (lost {c['dropped_loss']}, cut {c['dropped_cut']}, "
                     f"queue {c['dropped_queue'] + c['dropped_overflow']}, dup {c['duplicated']}, "
                     f"reord {c['reordered']})")  # fmt: skip
    return "  ".join(parts)


def table(rep: dict[str, Any]) -> Any:
    """A rich table of the counters, one column per direction."""
    from rich.table import Table

    t = Table(title=f"link-proxy {rep['a']} <-> {rep['b']}  t {rep['elapsed_s']:.1f} s"
              + ("  [bold red]CUT[/]" if rep["cut_now"] else ""))  # fmt: skip
    t.add_column("counter")
    t.add_column("a->b", justify="right")
    t.add_column("b->a", justify="right")
    for k in rep["a->b"]:
        t.add_row(k, str(rep["a->b"][k]), str(rep["b->a"][k]))
    return t


def run(args: argparse.Namespace) -> int:
    ab, ba = faults_from_args(args)
    proxy = LinkProxy(args.a, args.b, ab, ba, cuts=args.cut, seed=args.seed, trigger=args.trigger,
                      frames=args.frames)  # fmt: skip
    proxy.open()  # bind errors (a port in use) are one line, before anything runs
    stop = threading.Event()
    reason = {"why": "stopped"}

    def _stop(signum: int, frame: object) -> None:
        reason["why"] = signal.Signals(signum).name
        stop.set()

    def _cut(signum: int, frame: object) -> None:  # SIGUSR1 cuts the link, SIGUSR2 restores it
        (proxy.cut if signum == signal.SIGUSR1 else proxy.restore)()
        what = "cut" if signum == signal.SIGUSR1 else "restored"
        print(f"windseek link-proxy: {what} at t = {proxy.now():.3f} s ({signal.Signals(signum).name})",
              file=sys.stderr, flush=True)

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    old |= {s: signal.signal(s, _cut) for s in (signal.SIGUSR1, signal.SIGUSR2)}
    interactive = sys.stderr.isatty()
    every = args.progress_every if args.progress_every is not None else (1.0 if interactive else 10.0)
    try:
        proxy.start()
        cuts = ", ".join(f"{c.start_s:g}s+" + ("forever" if math.isinf(c.duration_s) else f"{c.duration_s:g}s")
                         for c in args.cut) or "none"  # fmt: skip
        print(f"windseek link-proxy: a {proxy.names[0]} <-> b {proxy.names[1]}; a->b {ab.describe()}; "
              f"b->a {ba.describe()}; cuts {cuts} after {args.trigger}; seed {args.seed}", file=sys.stderr, flush=True)
        _watch(proxy, stop, args.duration, every, interactive, reason)
    finally:
        rep = proxy.report()
        proxy.stop()
        for s, h in old.items():
            signal.signal(s, h)
    rep["stop_reason"] = reason["why"]
    if args.json:
        print(json.dumps(json_safe(rep), allow_nan=False), flush=True)
    else:
        from rich.console import Console

        Console(file=sys.stdout).print(table(rep))
        print(f"windseek link-proxy: {reason['why']} after {rep['elapsed_s']:.1f} s; cuts {rep['cuts']}")
    if proxy.error is not None:
        print(f"windseek link-proxy: error: the forwarding thread stopped: {proxy.error!r}", file=sys.stderr)
        return 2
    return 0


def _watch(proxy: LinkProxy, stop: threading.Event, duration: float | None, every: float, interactive: bool,
           reason: dict[str, str]) -> None:  # fmt: skip
    """Until a signal, the duration or a dead thread; progress every ``every`` s (a live table on a terminal)."""
    live: Any = None
    if interactive and every > 0:
        from rich.console import Console
        from rich.live import Live

        live = Live(table(proxy.report()), console=Console(stderr=True), auto_refresh=False)
        live.start()
    t_line = time.monotonic()
    try:
        while not stop.wait(min(0.2, every) if every > 0 else 0.2):
            if not proxy.running:
                reason["why"] = "error"
                return
            if duration is not None and proxy.now() >= duration:
                reason["why"] = f"duration {duration:g} s reached"
                return
            if every > 0 and time.monotonic() - t_line >= every:
                t_line = time.monotonic()
                if live is not None:
                    live.update(table(proxy.report()), refresh=True)
                else:
                    print(f"windseek link-proxy: {line(proxy.report())}", file=sys.stderr, flush=True)
    finally:
        if live is not None:
            live.stop()
