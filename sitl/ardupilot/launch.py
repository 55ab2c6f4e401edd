"""``windseek sitl SCENARIO --ardupilot``: windseek as ArduPilot SITL's JSON physics, served until a signal.

- ``--ardupilot-port [HOST:]PORT`` (default 127.0.0.1:9002): where windseek listens for ArduPilot's
  servo packets (ArduPilot SITL ``--model JSON[:IP]`` sends to port 9002 of that IP).
- ``--ardupilot-mavlink auto|HOST:PORT|none``: the ArduPilot serial port (TCP) the peripheral
  component (CHEM, ESC_STATUS, true wind; :mod:`sitl.ardupilot.peripheral`) connects to. ``auto``:
  SITL's ``SERIAL2``, 127.0.0.1:5763.
- ``--exit-summary PATH``: the summary as JSON at shutdown (wind RMSE of the forwarded WIND_COV, the
  declaration, counters, lockstep speed).
- ``--rrd PATH``: a Rerun recording, attached by the caller (``attach``: the command line's
  ``windseek.cmd_sitl``; nothing in ``sitl`` imports ``recording``) to the bridge's ``step_hooks`` and the
  runner's ``rx_hooks``.

ArduPilot's origin must be windseek's: start ArduCopter with the ``--home`` this prints.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sitl.ardupilot.bridge import ArduPilotBridge
from sitl.ardupilot.peripheral import ARDUPILOT_SERIAL2_PORT, TcpPeripheral
from sitl.ardupilot.runner import JsonOptions, JsonRunner
from sitl.hil.launch import close_all
from sitl.link.transports import parse_host_port
from sitl.scenario import load_scenario
from wire.jsonsafe import json_safe

#: The words of windseek's start line that say it listens for ArduPilot (tests and benchmarks wait for them).
LISTENING = "as ArduPilot's JSON physics on UDP"
#: windseek sitl's own autopilot options that do not apply when ArduPilot is the autopilot.
NOT_WITH_ARDUPILOT = ("udp", "tcp", "serial", "forward", "no_udp", "px4")


def add_options(p: argparse.ArgumentParser) -> None:
    """The ``--ardupilot`` option group of ``windseek sitl``."""
    g = p.add_argument_group("ArduPilot flies (windseek as ArduPilot SITL's JSON physics, lockstep; "
                             "see sitl/ardupilot/)")
    g.add_argument("--ardupilot", action="store_true", help="ArduPilot SITL (--model JSON) flies the scenario's world "
                   "on windseek's IMU; the built-in autopilot is off")
    g.add_argument("--ardupilot-port", default="9002", metavar="[HOST:]PORT",
                   help="UDP port ArduPilot sends its servo packets to (default 127.0.0.1:9002)")
    g.add_argument("--ardupilot-mavlink", default="auto", metavar="auto|HOST:PORT|none",
                   help="ArduPilot serial port (TCP) for windseek's sensor component 158 (CHEM, ESC_STATUS, "
                   f"true wind): auto = SITL's SERIAL2, 127.0.0.1:{ARDUPILOT_SERIAL2_PORT}")
    g.add_argument("--ardupilot-spin", type=float, default=JsonOptions.spin_s, metavar="S",
                   help="wall seconds to spin for ArduPilot's next packet while frames come back to back, before "
                   "sleeping (0 = never; spinning halves the hand-off cost on a fast run and uses a core)")


def home_arg(bridge: ArduPilotBridge) -> str:
    """ArduPilot SITL's ``--home LAT,LON,ALT,YAW`` for windseek's NED origin (yaw 0: ArduPilot's default)."""
    h = bridge.scenario.sensors.home
    return f"{h.lat_deg:.7f},{h.lon_deg:.7f},{h.alt_m:g},0"


def make_runner(args: argparse.Namespace, say: Any) -> JsonRunner:
    """Scenario, world, UDP socket and peripheral from the parsed ``windseek sitl`` arguments."""
    given = [f"--{n.replace('_', '-')}" for n in NOT_WITH_ARDUPILOT if getattr(args, n, None)]
    if given:
        raise ValueError(f"{', '.join(given)}: not with --ardupilot (ArduPilot is the autopilot: connect MAVSDK, "
                         "MAVProxy and windseek mission/estimator to ArduPilot's MAVLink ports)")  # fmt: skip
    host, port = parse_host_port(args.ardupilot_port, "127.0.0.1")
    bridge = ArduPilotBridge(load_scenario(args.scenario), seed=args.seed, say=say)
    spec = args.ardupilot_mavlink
    periph = None
    if spec != "none":
        target = ("127.0.0.1", ARDUPILOT_SERIAL2_PORT) if spec == "auto" else parse_host_port(spec)
        periph = TcpPeripheral(target)
    spin = float(args.ardupilot_spin)
    if not (spin >= 0 and spin <= 0.1):
        raise ValueError(f"--ardupilot-spin {spin:g}: must be within 0-0.1 s")
    return JsonRunner(bridge, JsonOptions(host=host, port=port, spin_s=spin), periph, say)


def run_ardupilot(args: argparse.Namespace, attach: Callable[[JsonRunner], list[Any]] | None = None) -> int:
    """Serve until SIGINT/SIGTERM; one line per event and a summary line at the end. ``attach(runner)``
    hooks listeners (a recording) on the runner before it serves and returns them: each is closed at the end."""

    def say(text: str) -> None:
        print(f"windseek sitl: {text}", file=sys.stderr, flush=True)

    runner = make_runner(args, say)
    try:
        parts = attach(runner) if attach is not None else []
    except Exception:
        runner.close()
        raise
    old = {s: signal.signal(s, lambda *_: runner.stop()) for s in (signal.SIGINT, signal.SIGTERM)}
    b = runner.bridge
    periph = "off" if runner.peripheral is None else runner.peripheral.name
    print(f"windseek sitl: {b.scenario.name} {LISTENING} {runner.options.host}:{runner.port} "
          f"(peripheral component 158 on {periph}); start ArduCopter with --model JSON --home {home_arg(b)}",
          flush=True)  # fmt: skip
    try:
        runner.serve()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        runner.close()
        close_all(parts, say)
    d = json_safe(runner.summary())
    if getattr(args, "exit_summary", None):
        p = Path(args.exit_summary)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(d, indent=1, allow_nan=False) + "\n")
    say(f"stopped at t = {b.t:.2f} s; {d['frames']} frames ({d['resends']} resends, {d['restarts']} restarts), "
        f"lockstep speed {d.get('lockstep_speed')}")
    return 0
