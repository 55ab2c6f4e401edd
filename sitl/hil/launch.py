"""``windseek sitl SCENARIO --px4``: the runner built from the command line, served until a signal.

- ``--px4-port [HOST:]PORT`` (default 127.0.0.1:4560): the TCP port PX4 SITL connects to,
  4560 + PX4 instance (``px4 -i N``).
- ``--px4-serial DEV[:BAUD]`` (default 921600 baud): HITL, a flight controller with ``SYS_HITL 1``.
- ``--px4-mavlink auto|HOST:PORT|none``: where the peripheral component (CHEM, ESC_STATUS, true
  wind; :mod:`sitl.hil.peripheral`) talks to PX4. ``auto``: SITL's payload link
  127.0.0.1:14280 + instance, or the serial link itself in HITL.
- ``--speed K``: simulated seconds per wall second in lockstep; ``--px4-free``: as fast as PX4 answers.
- ``--px4-timeout S``: wall seconds to wait for a lockstep answer (then it steps on, counted).
- ``--exit-summary PATH``: the runner's summary as JSON at shutdown (wind RMSE of the forwarded
  WIND_COV, the declaration, counters, the lockstep speed realised against the requested pace and the
  steps' throughput); ``--tlog PATH``: every frame both links
  carried.
- ``--rrd PATH``: a Rerun recording, attached by the caller (``attach``: the command line's
  ``windseek.cmd_sitl``; nothing in ``sitl`` imports ``recording``) to the bridge's ``step_hooks`` and the
  runner's ``rx_hooks``.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sitl.hil.bridge import HilBridge
from sitl.hil.peripheral import PERIPHERAL_COMPONENT, PX4_PAYLOAD_PORT, PX4_SIM_PORT, SharedPeripheral, UdpPeripheral
from sitl.hil.px4_link import SerialSimLink, SimLink, TcpSimLink
from sitl.hil.runner import HilOptions, HilRunner
from sitl.link.transports import parse_host_port, parse_serial
from sitl.scenario import load_scenario
from wire.jsonsafe import json_safe

HITL_BAUD = 921600
#: windseek sitl's own autopilot options that do not apply when PX4 is the autopilot.
NOT_WITH_PX4 = ("udp", "tcp", "serial", "forward", "no_udp")


def make_runner(args: argparse.Namespace, say: Any) -> HilRunner:
    """Scenario, world, link to PX4 and peripheral from the parsed ``windseek sitl`` arguments."""
    given = [f"--{n.replace('_', '-')}" for n in NOT_WITH_PX4 if getattr(args, n, None)]
    if given:
        raise ValueError(f"{', '.join(given)}: not with --px4 (PX4 is the autopilot: connect MAVSDK, QGroundControl "
                         "and windseek mission/estimator to PX4's MAVLink ports)")  # fmt: skip
    speed = 0.0 if getattr(args, "px4_free", False) else float(args.speed)
    opts = HilOptions(speed=speed, answer_timeout_s=float(args.px4_timeout))
    opts.validate()
    bridge = HilBridge(load_scenario(args.scenario), seed=args.seed, say=say)
    link: SimLink
    if args.px4_serial:
        dev, baud = parse_serial(args.px4_serial)
        baud = baud if ":" in args.px4_serial else HITL_BAUD
        link = SerialSimLink(dev, baud, 1, PERIPHERAL_COMPONENT)
        instance = 0
    else:
        host, port = parse_host_port(args.px4_port, "127.0.0.1")
        link = TcpSimLink(host, port, 1, PERIPHERAL_COMPONENT)
        instance = port - PX4_SIM_PORT if PX4_SIM_PORT <= port < PX4_SIM_PORT + 100 else 0
    link.encoder.srcSystem = instance + 1  # PX4 SITL: MAV_SYS_ID = instance + 1 (learned from PX4 anyway)
    try:
        peripheral = _peripheral(args.px4_mavlink, link, instance)
    except Exception:
        link.close()
        raise
    return HilRunner(bridge, link, peripheral, opts, say)


def _peripheral(spec: str, link: SimLink, instance: int) -> Any:
    if spec == "none":
        return None
    if spec == "auto" and isinstance(link, SerialSimLink):
        return SharedPeripheral(link)
    target = ("127.0.0.1", PX4_PAYLOAD_PORT + instance) if spec == "auto" else parse_host_port(spec)
    return UdpPeripheral(target, instance + 1)


def close_all(parts: list[Any], say: Callable[[str], None]) -> None:
    """``close()`` each listener; one that fails is said and does not stop the others."""
    for part in parts:
        try:
            part.close()
        except Exception as e:  # noqa: BLE001 - one failing listener must not lose the others
            say(f"could not finish {type(part).__name__}: {e}")


def run_px4(args: argparse.Namespace, attach: Callable[[HilRunner], list[Any]] | None = None) -> int:
    """Serve until SIGINT/SIGTERM; print one line per event and a summary line at the end. ``attach(runner)``
    hooks listeners (a recording) on the runner before it serves and returns them: each is closed at the end."""

    def say(text: str) -> None:
        print(f"windseek sitl: {text}", file=sys.stderr, flush=True)

    runner = make_runner(args, say)
    try:
        parts = attach(runner) if attach is not None else []
    except Exception:
        runner.link.close()
        if runner.peripheral is not None:
            runner.peripheral.close()
        raise
    tlog = _tlog(runner, getattr(args, "tlog", None))
    old = {s: signal.signal(s, lambda *_: runner.stop()) for s in (signal.SIGINT, signal.SIGTERM)}
    b = runner.bridge
    periph = "off" if runner.peripheral is None else runner.peripheral.name
    print(f"windseek sitl: {b.scenario.name} as PX4's simulator on {runner.link.name} (peripheral component "
          f"{PERIPHERAL_COMPONENT} on {periph}); waiting for PX4", flush=True)  # fmt: skip
    try:
        runner.serve()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        runner.link.close()
        if runner.peripheral is not None:
            runner.peripheral.close()
        if tlog is not None:
            tlog.close()
        close_all(parts, say)
    d = json_safe(runner.summary())
    if getattr(args, "exit_summary", None):
        p = Path(args.exit_summary)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(d, indent=1, allow_nan=False) + "\n")
    say(f"stopped at t = {b.t:.2f} s ({runner.state.value}); {d.get('answers', 0)} PX4 answers, "
        f"{d.get('lockstep_timeouts', 0)} lockstep timeouts, {runner.speed_line()}")
    return 0


def _tlog(runner: HilRunner, path: str | None) -> Any:
    if not path:
        return None
    from sitl.link.tlog import TlogWriter

    w = TlogWriter(path)
    runner.link.tap = lambda frame, sent: w.write(frame)
    return w
