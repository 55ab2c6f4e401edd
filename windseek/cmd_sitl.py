"""``windseek sitl SCENARIO``: the simulator as a MAVLink 2 autopilot (PX4 dialect of modes), paced in real time.

By default it sends on UDP to 127.0.0.1:14540 (API, like PX4's onboard link) and
127.0.0.1:14550 (ground station), from an ephemeral local port, and answers whoever talks to it.
``--udp`` replaces those peers; ``--udp-bind`` fixes the local port (for ``udpout://`` clients);
``--tcp PORT`` adds a TCP server, ``--serial DEV[:BAUD]`` a serial port. It runs until SIGINT or
SIGTERM and then closes every link.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from typing import Any

from sitl.link import SerialTransport, SitlLink, TcpServerTransport, UdpTransport
from sitl.link.transports import Transport, parse_host_port, parse_serial
from sitl.scenario import load_scenario
from sitl.simulation import Simulation
from wire.dialect import mavlink
from wire.signing import load_key

DEFAULT_UDP_PEERS = ["127.0.0.1:14540", "127.0.0.1:14550"]


def _rate_hz(text: str) -> float:
    """A rate >= 0 Hz (argparse type): '-1', 'nan' and 'inf' are errors."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (Hz)") from None
    if not (math.isfinite(v) and v >= 0.0):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a finite rate >= 0 Hz")
    return v


def _speed(text: str) -> float:
    """A speed factor > 0 (argparse type)."""
    v = _rate_hz(text)
    if v <= 0.0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be > 0")
    return v


def _altitude(text: str) -> float:
    """A height above the ground > 0 m (argparse type)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (m)") from None
    if not (math.isfinite(v) and v > 0.0):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a finite height > 0 m")
    return v


def _box(text: str) -> tuple[list[float], list[float]]:
    """``N,E,D,N,E,D`` (two opposite corners of a box, m NED) as (min corner, max corner)."""
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected six numbers N,E,D,N,E,D in metres") from None
    if len(v) != 6 or not all(math.isfinite(x) for x in v):
        raise argparse.ArgumentTypeError(f"{text!r}: expected six finite numbers N,E,D,N,E,D, got {len(v)}")
    pairs = list(zip(v[:3], v[3:], strict=True))
    return [min(a, b) for a, b in pairs], [max(a, b) for a, b in pairs]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sitl",
        help="run a scenario as a MAVLink autopilot (MAVSDK, pymavlink, QGroundControl, MAVProxy)",
        description="Run a scenario in real time (times --speed) behind a MAVLink 2 endpoint that behaves "
        "like a PX4 autopilot: system 1, component 1.",
    )
    p.add_argument("scenario", help="built-in scenario name or path to a scenario .toml")
    p.add_argument("--speed", type=_speed, default=1.0, help="simulation seconds per wall-clock second (default 1)")
    p.add_argument("--udp", action="extend", nargs="+", metavar="HOST:PORT",
                   help="UDP peers to stream to (one or more, repeatable; default 127.0.0.1:14540 127.0.0.1:14550)")
    p.add_argument("--udp-bind", default="0.0.0.0:0", metavar="HOST:PORT",
                   help="local UDP address (default an ephemeral port on all interfaces)")
    p.add_argument("--no-udp", action="store_true", help="no UDP link at all")
    p.add_argument("--tcp", type=int, metavar="PORT", help="also serve MAVLink on a TCP server port")
    p.add_argument("--serial", metavar="DEV[:BAUD]", help="also serve MAVLink on a serial device (default 57600 baud)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    p.add_argument("--true-wind-hz", type=_rate_hz, default=5.0,
                   help="rate of the simulation-only TRUEWN/TRUEWE/TRUEWD values (0 = off)")
    p.add_argument("--hil-decimation", type=int, default=1, metavar="N",
                   help="send HIL_SENSOR for every N-th IMU sample (default 1: the IMU rate)")
    p.add_argument("--signing-key", metavar="FILE", default=None,
                   help="MAVLink 2 signing on every link: FILE holds the 32-byte key as 64 hex characters "
                   "(default: $WINDSEEK_SIGNING_KEY if set); unsigned or wrongly signed frames are dropped")
    p.add_argument("--allow-sim-params", action="store_true",
                   help="let MAVLink PARAM_SET change the simulation knobs SIM_* (refused by default)")
    # ---- attachments to the link: tlog, forwarding, exit summary (sitl.link), recording (recording.sitl_link)
    g = p.add_argument_group("logs, forwarding and truth (sitl/link/, recording/sitl_link.py)")
    g.add_argument("--tlog", metavar="PATH", help="write every MAVLink frame sent and received to a .tlog "
                   "(8-byte big-endian wall-clock UNIX time in us + frame)")
    g.add_argument("--rrd", metavar="PATH", help="write a Rerun recording: the simulation's truth plus the "
                   "WIND_COV estimates, mission status and declared source that arrive on the wire; with --px4 or "
                   "--ardupilot also the autopilot's own wind estimate (PX4 EKF2's WIND_COV, ArduCopter EKF3's WIND) "
                   "on the same wind plots, and its flight mode")
    g.add_argument("--rrd-strategy", metavar="NAME", default=None, help="strategy name stored in the recording")
    g.add_argument("--rrd-altitude", metavar="M", default=None, type=_altitude,
                   help="height of the recorded urban wind field's horizontal slice, m above the ground "
                   "(default: the scenario's take-off altitude; windseek demo passes the mission's search altitude)")
    g.add_argument("--geofence", metavar="N,E,D,N,E,D", default=None, type=_box,
                   help="geofence box corners (m, NED) drawn in the recording (the mission's box)")
    g.add_argument("--forward", action="store_true", help="forward frames not addressed to the autopilot to the "
                   "other links and peers (PX4 MAV_X_FORWARD), e.g. an estimator's WIND_COV to the mission")
    g.add_argument("--exit-summary", metavar="PATH", help="write a JSON file at shutdown with truth-based figures: "
                   "wind RMSE of the received WIND_COV, true and declared source, path length, final state")
    _add_px4_options(p)
    from sitl.ardupilot.launch import add_options

    add_options(p)
    p.set_defaults(func=run)


def _add_px4_options(p: argparse.ArgumentParser) -> None:
    """``--px4``: windseek as PX4's simulator (sitl/hil/; README "Pointing it at a real autopilot")."""
    g = p.add_argument_group("PX4 flies (windseek as PX4's simulator, lockstep; see sitl/hil/)")
    g.add_argument("--px4", action="store_true", help="PX4 SITL (TCP) or a flight controller in HITL (serial) flies "
                   "the scenario's world on windseek's sensors; the built-in autopilot is off")
    g.add_argument("--px4-free", action="store_true",
                   help="lockstep as fast as PX4 answers, instead of at --speed (PX4 SITL only)")
    g.add_argument("--px4-port", default="4560", metavar="[HOST:]PORT",
                   help="TCP port PX4 SITL connects to: 4560 + PX4 instance (default 127.0.0.1:4560)")
    g.add_argument("--px4-serial", metavar="DEV[:BAUD]",
                   help="HITL: a flight controller with SYS_HITL 1 on a serial/USB port (default 921600 baud)")
    g.add_argument("--px4-mavlink", default="auto", metavar="auto|HOST:PORT|none",
                   help="PX4 MAVLink instance that forwards windseek's sensor component 158 (CHEM, ESC_STATUS, true "
                   "wind) to the companions: auto = SITL's payload link 127.0.0.1:14280+instance, or the HITL serial "
                   "link itself")
    g.add_argument("--px4-timeout", type=float, default=2.0, metavar="S",
                   help="wall seconds to wait for PX4's answer to a lockstep step before stepping on (counted)")


def build(args: argparse.Namespace) -> SitlLink:
    """Scenario, simulation, transports and link from the parsed arguments; every argument is
    checked before anything slow (the simulation's first build compiles its kernels) or open."""
    key = load_key(getattr(args, "signing_key", None))  # a bad key fails here, before any socket opens
    peers = [parse_host_port(x) for x in (args.udp or DEFAULT_UDP_PEERS)] if not args.no_udp else []
    bind = parse_host_port(args.udp_bind, "0.0.0.0")
    serial = parse_serial(args.serial) if args.serial else None
    if args.no_udp and args.tcp is None and serial is None:
        raise ValueError("no link: give --udp, --tcp or --serial (or drop --no-udp)")
    if args.hil_decimation < 1:
        raise ValueError(f"--hil-decimation {args.hil_decimation}: must be an integer >= 1")
    sc = load_scenario(args.scenario)
    sim = Simulation(sc, seed=args.seed, autostart_route=False)
    transports: list[Transport] = []
    try:
        if not args.no_udp:
            transports.append(UdpTransport(peers, bind))
        if args.tcp is not None:
            transports.append(TcpServerTransport(args.tcp))
        if serial is not None:
            transports.append(SerialTransport(*serial))
        link = SitlLink(sim, transports, speed=args.speed, true_wind_hz=args.true_wind_hz, signing_key=key,
                        allow_sim_params=getattr(args, "allow_sim_params", False))
        imu_hz = sc.sensors.imu.rate_hz
        link.streams.set_interval(mavlink.MAVLINK_MSG_ID_HIL_SENSOR, 1e6 * args.hil_decimation / imu_hz, 0.0)
        return link
    except Exception:
        for t in transports:
            t.close()
        raise


def _attach_wire(link: SitlLink, args: argparse.Namespace) -> list:
    """The optional --tlog / --forward / --rrd / --exit-summary attachments; returns those to close."""
    from recording.sitl_link import LinkRecorder
    from sitl.link.forwarding import Forwarder
    from sitl.link.tlog import TlogWriter
    from sitl.link.truth_summary import TruthSummary

    out: list = []
    if getattr(args, "tlog", None):
        out.append(TlogWriter(args.tlog).attach(link))
    if getattr(args, "forward", False):
        Forwarder(link)
    if getattr(args, "rrd", None):
        out.append(LinkRecorder(link, args.rrd, strategy=args.rrd_strategy, geofence_ned=args.geofence,
                                field_altitude_m=getattr(args, "rrd_altitude", None)))
    if getattr(args, "exit_summary", None):
        out.append(TruthSummary(link, args.exit_summary))
    return out


def attach_autopilot_rrd(runner: Any, args: argparse.Namespace, autopilot: str) -> list:
    """--rrd with PX4 or ArduPilot flying: the recorder on the runner's hooks (recording/autopilot_rrd.py)."""
    if not getattr(args, "rrd", None):
        return []
    from recording.autopilot_rrd import AutopilotRecorder

    return [AutopilotRecorder(runner, args.rrd, autopilot, strategy=args.rrd_strategy, geofence_ned=args.geofence,
                              field_altitude_m=getattr(args, "rrd_altitude", None))]  # fmt: skip


def _close_wire(parts: list) -> None:
    for part in parts:
        try:
            part.close()
        except Exception as e:  # noqa: BLE001 - one failing log must not lose the others
            print(f"windseek sitl: could not finish {type(part).__name__}: {e}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    if getattr(args, "px4", False):
        from recording.autopilot_rrd import PX4_LABEL
        from sitl.hil.launch import run_px4

        return run_px4(args, attach=lambda runner: attach_autopilot_rrd(runner, args, PX4_LABEL))
    if getattr(args, "ardupilot", False):
        from recording.autopilot_rrd import ARDUCOPTER_LABEL
        from sitl.ardupilot.launch import run_ardupilot

        return run_ardupilot(args, attach=lambda runner: attach_autopilot_rrd(runner, args, ARDUCOPTER_LABEL))
    link = build(args)
    try:
        wire = _attach_wire(link, args)
    except Exception:
        link.endpoint.close()
        raise

    def _stop(signum: int, frame: object) -> None:
        link._stop.set()

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    names = ", ".join(lk.name for lk in link.endpoint.links)
    print(f"windseek sitl: {link.sim.scenario.name} at speed {link.speed:g} on {names}", flush=True)
    if link.endpoint.signing_on:
        print("windseek sitl: MAVLink 2 signing on: unsigned or wrongly signed frames are dropped", flush=True)
    try:
        link.serve()
    finally:
        link.endpoint.close()
        _close_wire(wire)
        for s, h in old.items():
            signal.signal(s, h)
    c = link.counters
    rejected = (f", {c['rx_unauthenticated']} unauthenticated dropped, {c['rx_mavlink1_signing']} MAVLink 1 while "
                "signing is on" if link.endpoint.signing_on else "")  # fmt: skip
    print(f"windseek sitl: stopped at t = {link.sim.t:.2f} s; rx {c['rx_messages']} msgs "
          f"({c['rx_bad']} bad{rejected}), tx {c['tx_messages']} msgs", file=sys.stderr, flush=True)
    return 0
