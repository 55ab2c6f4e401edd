"""``windseek estimator --connect URL``: the wind UKF as a MAVLink companion process, publishing WIND_COV.

Connects with pymavlink to an autopilot (``windseek sitl``, PX4, ArduPilot) over UDP, TCP or
serial and hands every message to :class:`~estimator.live.LiveCore`, which locks on to the
autopilot, picks the inputs, gates the ground, follows clock resets and runs the UKF (see
``estimator/live.py``). This module is the I/O around it: the connection, the WIND_COV
publication (air-mass velocity NED, m/s; variances m^2/s^2) as system = the autopilot's,
component 191 (MAV_COMP_ID_ONBOARD_COMPUTER), a 1 Hz HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER),
SET_MESSAGE_INTERVAL requests for missing inputs, signals, progress lines and the summary. A
router between the programs (mavlink-router, ``windseek sitl --forward``) passes WIND_COV on to
the mission and ground stations; PX4 forwards it only to its other MAVLink instances
(``MAV_X_FORWARD``), and MAVProxy only to its master (README, "One serial link, several programs").

WIND_COV is published only for an estimate the filter made: not before it has run, not while
the vehicle is on the ground or landing, not after a restart until the new filter has run.

URLs (MAVSDK style, or pymavlink's own): ``udpin://0.0.0.0:14550`` (listen), ``udpout://HOST:PORT``
(send first), ``tcpout://HOST:PORT`` (connect), ``tcpin://0.0.0.0:PORT``,
``serial:///dev/ttyUSB0:57600``; ``udpin:0.0.0.0:14550``, ``tcp:HOST:PORT``, ``/dev/ttyACM0``.

It stops on SIGINT/SIGTERM, after ``--duration`` seconds of vehicle time, or when the link has
been quiet for ``--link-timeout`` wall seconds, and prints a summary (``--json``: one object).
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import struct
import sys
import time
from typing import Any

import numpy as np

from estimator.live import LiveConfig, LiveCore
from estimator.mavlink_adapter import wind_cov_message
from estimator.mavlink_decode import MAV_AUTOPILOT_PX4, PREFERENCE
from estimator.worker import warm_up
from windseek.estimator_px4_mag import Px4MagSetup
from wire.jsonsafe import json_safe
from wire.names import ESTIMATOR_COMPONENT
from wire.urls import pymavlink_url  # in wire/: the mission's signing bridge uses it too

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
#: Per input group, the messages asked for (SET_MESSAGE_INTERVAL, Hz) when none of the group streams.
WANTED: dict[str, tuple[tuple[str, float], ...]] = {
    "imu": (("HIGHRES_IMU", 100.0),),
    "attitude": (("ATTITUDE_QUATERNION", 50.0),),
    "velocity": (("LOCAL_POSITION_NED", 30.0),),
    "rotors": (("ESC_STATUS", 50.0), ("ACTUATOR_OUTPUT_STATUS", 50.0)),
}

#: Rate asked for EXTENDED_SYS_STATE when it does not stream [Hz].
STATE_HZ = 5.0


def _range(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(",")
    try:
        r = (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected MIN,MAX, e.g. 1000,2000") from None
    if not (sep and math.isfinite(r[0]) and math.isfinite(r[1]) and r[1] > r[0]):
        raise argparse.ArgumentTypeError(f"{text!r}: expected MIN,MAX with MIN < MAX")
    return r


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "estimator",
        help="run the wind estimator live on an autopilot's MAVLink telemetry and publish WIND_COV",
        description="Connect to an autopilot (windseek sitl, PX4, ArduPilot), run the wind UKF on its IMU, "
        "attitude, velocity and rotor-speed telemetry and publish the estimate as WIND_COV on the same link.",
    )
    p.add_argument("--connect", required=True, metavar="URL",
                   help="udpin://0.0.0.0:14550, udpout://HOST:PORT, tcpout://HOST:PORT, serial:///dev/ttyUSB0:57600 "
                   "(or a pymavlink device string)")
    p.add_argument("--publish", action=argparse.BooleanOptionalAction, default=True,
                   help="send WIND_COV back on the link (default on; --no-publish only listens)")
    p.add_argument("--rate", type=float, default=10.0, metavar="HZ",
                   help="WIND_COV rate, Hz of vehicle time (default 10)")
    p.add_argument("--vehicle", default="nasa_quad", help="vehicle file of the force model (name or path)")
    p.add_argument("--esc-order", choices=("sitl", "px4", "ardupilot"), default="sitl",
                   help="numbering of ESC telemetry and actuator outputs: windseek SITL (its rotor order, outputs "
                   "1000-2000 = 0..max rotor speed), PX4 quad-X (outputs 1000-2000 = min..max rotor speed) or "
                   "ArduCopter quad X (PX4's numbering; windseek's ESC under ArduPilot: 1000-2000 = 0..max)")
    p.add_argument("--output-range", type=_range, default=(1000.0, 2000.0), metavar="MIN,MAX",
                   help="actuator output values at zero and full command (PWM us; default 1000,2000)")
    p.add_argument("--thr-mdl-fac", type=float, default=None, metavar="F",
                   help="the autopilot's THR_MDL_FAC: thrust = F u^2 + (1-F) u of the output u, rotor speed from "
                   "thrust (default: rotor speed linear in u); see estimator/motor_output.py")
    p.add_argument("--airframe", default=None, metavar="TEXT",
                   help="the vehicle flown when it is not the vehicle file's (e.g. 'PX4 SIH quadrotor'): said in the "
                   "output and the summary (the estimate is biased by the model mismatch)")
    p.add_argument("--target-system", type=int, default=None, metavar="N",
                   help="lock on to the autopilot of this system id (default: the first autopilot HEARTBEAT)")
    p.add_argument("--imu-average", type=int, default=1, metavar="N",
                   help="average N consecutive IMU samples per filter step (cost / N; default 1)")
    p.add_argument("--request-rates", choices=("missing", "always", "never"), default="missing",
                   help="SET_MESSAGE_INTERVAL for the inputs at start: those not streaming (default), all, none")
    p.add_argument("--ground-gate", action=argparse.BooleanOptionalAction, default=True,
                   help="pause the filter while the autopilot reports the vehicle on the ground or landing "
                   "(EXTENDED_SYS_STATE) and replace a filter that flew at the next take-off (default on)")
    p.add_argument("--system-id", type=int, default=None, help="our MAVLink system id (default: the autopilot's)")
    p.add_argument("--esc-component", type=int, default=None, metavar="ID",
                   help="rotor speeds (ESC_STATUS, RAW_RPM, ESC_INFO) from this MAVLink component of the autopilot's "
                   "system (158 with windseek sitl --px4, whose PX4 sends a placeholder ESC_STATUS of its own; "
                   "default: the autopilot's own)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds of vehicle time")
    p.add_argument("--link-timeout", type=float, default=10.0, metavar="S",
                   help="stop when nothing arrived for S wall seconds (0 = never; default 10)")
    p.add_argument("--connect-timeout", type=float, default=30.0, metavar="S",
                   help="wall seconds to wait for the autopilot's first HEARTBEAT (default 30)")
    p.add_argument("--signing-key", metavar="FILE", default=None,
                   help="MAVLink 2 signing: FILE holds the 32-byte key as 64 hex characters (default: "
                   "$WINDSEEK_SIGNING_KEY if set); sign what we send, drop unsigned or wrongly signed frames")
    p.add_argument("--compass", action=argparse.BooleanOptionalAction, default=True,
                   help="check the autopilot's heading against its magnetometer and correct the attitude by the "
                   "offset (estimator/compass.py; default on)")
    p.add_argument("--compass-sigma-deg", type=float, default=1.0, metavar="DEG",
                   help="stated 1-sigma of the compass heading (calibration, declination, interference)")
    p.add_argument("--px4-raw-compass", action=argparse.BooleanOptionalAction, default=True,
                   help="on PX4: read its CAL_MAG parameters and take SCALED_IMU as the IMU (no EKF2 biases taken out) "
                   "with its raw field calibrated with them for the compass check, not HIGHRES_IMU, whose biases make "
                   "it agree with EKF2's heading (windseek/estimator_px4_mag.py; default on)")
    p.add_argument("--px4-scaled-imu-hz", type=float, default=100.0, metavar="HZ",
                   help="rate asked for PX4's SCALED_IMU when it is taken (default 100)")
    p.add_argument("--tlog", default=None, metavar="PATH",
                   help="write every message received to this telemetry log (replay: benchmarks/compass_replay.py)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    p.add_argument("--progress-every", type=float, default=None, metavar="S",
                   help="wall seconds between progress lines on stderr (default: a live line on a terminal, "
                   "every 10 s otherwise; 0 = none)")
    p.set_defaults(func=run)


def make_core(args: argparse.Namespace) -> LiveCore:
    """The live core the command line describes (errors are one-line ValueErrors)."""
    from estimator.compass import CompassConfig
    from estimator.motor_output import MOTOR_ORDERS, OutputMap
    from vehicle.vehicle_file import load_vehicle

    if not (math.isfinite(args.rate) and args.rate > 0):
        raise ValueError(f"--rate {args.rate}: must be > 0")
    vehicle = load_vehicle(args.vehicle)
    outputs = OutputMap.for_vehicle(vehicle, args.esc_order, args.thr_mdl_fac, tuple(args.output_range))
    cfg = LiveConfig(vehicle=vehicle, imu_average=args.imu_average, ground_gate=args.ground_gate,
                     target_system=args.target_system, esc_order=MOTOR_ORDERS[args.esc_order], outputs=outputs,
                     airframe=args.airframe, esc_component=args.esc_component,
                     compass=CompassConfig(enabled=args.compass, sigma_deg=args.compass_sigma_deg))  # fmt: skip
    return LiveCore(cfg)


class Publisher:
    """WIND_COV at ``rate`` Hz of vehicle time, for estimates the filter made (never while paused)."""

    def __init__(self, core: LiveCore, rate_hz: float) -> None:
        self.core = core
        self.period = 1.0 / rate_hz
        self.next_t = -math.inf
        self.sent = 0

    def due(self) -> Any | None:
        """The WIND_COV message to send now, or None."""
        core = self.core
        t = core.t
        if not math.isfinite(t) or core.paused():
            return None
        if t + self.period < self.next_t:
            self.next_t = t  # the autopilot's clock went back (a reboot): follow it
        if t < self.next_t:
            return None
        out = core.output()
        if out is None:
            return None
        self.next_t = t + self.period
        return wind_cov_message(out.t, out.wind_ned, out.cov_ned)


def summary(core: LiveCore, pub: Publisher, reason: str) -> dict[str, Any]:
    """The final report: the core's figures plus speed and from-direction, publication count, stop reason."""
    from recording.sim_hook import wind_speed_from_deg

    s = core.summary()
    w = s["wind_ned_m_s"]
    speed, from_deg = wind_speed_from_deg(np.array(w)) if w is not None else (math.nan, math.nan)
    chosen = dict(s["inputs"])
    s.update({"duration_s": round(core.elapsed_s, 3), "speed_m_s": round(speed, 3), "from_deg": round(from_deg, 1),
              "wind_cov_published": pub.sent, "imu_message": chosen.pop("imu", None), "inputs": chosen,
              "stop_reason": reason})  # fmt: skip
    return json_safe(s)


def line(core: LiveCore, pub: Publisher) -> str:
    """The progress line: the estimate, or what the estimator is waiting for."""
    from recording.sim_hook import wind_speed_from_deg

    out = core.output()
    if out is None or core.paused():
        return f"t {core.t:7.1f} s  {core.status_line()}  WIND_COV sent {pub.sent}"
    w = out.wind_ned
    sig = np.sqrt(np.maximum(np.diag(out.cov_ned), 0.0))
    speed, from_deg = wind_speed_from_deg(w)
    return (f"t {core.t:7.1f} s  wind N {w[0]:+5.2f} E {w[1]:+5.2f} D {w[2]:+5.2f} m/s "
            f"(+-{sig[0]:.2f} {sig[1]:.2f} {sig[2]:.2f}) = {speed:4.1f} m/s from {from_deg:5.1f} deg  "
            f"WIND_COV sent {pub.sent}")  # fmt: skip


def request_rates(conn: Any, core: LiveCore, mode: str, say: Any) -> None:
    """SET_MESSAGE_INTERVAL for the input groups with nothing streaming (``missing``), or all (``always``)."""
    if mode == "never" or core.target is None:
        return
    from wire.dialect import mavlink

    for group, wanted in WANTED.items():
        if mode == "missing" and any(core.select.seen[n] for n in PREFERENCE[group]):
            continue
        for name, hz in wanted:
            msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
            conn.mav.command_long_send(core.target[0], core.target[1], MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                       float(msg_id), 1e6 / hz, 0, 0, 0, 0, 0)  # fmt: skip
            say(f"requested {name} (message {msg_id}) at {hz:g} Hz for the {group} input")
    # The landed state gates the filter and the model's verdict (in the air only): PX4 streams it,
    # ArduPilot only in its EXTENDED_STATUS group, which a companion port does not stream by default.
    if mode == "always" or core.landed_state is None:
        msg_id = mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
        conn.mav.command_long_send(core.target[0], core.target[1], MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                   float(msg_id), 1e6 / STATE_HZ, 0, 0, 0, 0, 0)  # fmt: skip
        say(f"requested EXTENDED_SYS_STATE (message {msg_id}) at {STATE_HZ:g} Hz for the landed state")
    # The autopilot's own heading uncertainty (PX4: EKF2's yaw variance in ODOMETRY) for the stated covariance.
    if core.config.compass.autopilot_sigma and (mode == "always" or core.compass_feed.autopilot_yaw_sigma is None):
        msg_id = mavlink.MAVLINK_MSG_ID_ODOMETRY
        conn.mav.command_long_send(core.target[0], core.target[1], MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                   float(msg_id), 1e6 / STATE_HZ, 0, 0, 0, 0, 0)  # fmt: skip
        say(f"requested ODOMETRY (message {msg_id}) at {STATE_HZ:g} Hz for the autopilot's heading uncertainty")


def run(args: argparse.Namespace) -> int:
    from pymavlink import mavutil

    from wire.dialect import mavlink as dialect

    # The windseek dialect (common + ESC_INFO/ESC_STATUS) for every connection made below.
    mavutil.mavlink = dialect
    mavutil.current_dialect = "windseek"
    from wire import signing
    from wire.resync import resync_connection

    key = signing.load_key(getattr(args, "signing_key", None))  # a bad key: one-line error, nothing opened
    device, baud = pymavlink_url(args.connect)
    interactive = sys.stderr.isatty()
    every = args.progress_every if args.progress_every is not None else (0.5 if interactive else 10.0)
    stop: list[str] = []

    def say(text: str) -> None:
        if interactive and every > 0:
            sys.stderr.write("\r\x1b[K")
        print(f"windseek estimator: {text}", file=sys.stderr, flush=True)

    def _stop(signum: int, frame: object) -> None:
        stop.append(signal.Signals(signum).name)

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        core = make_core(args)
        warm_up(core.config)  # a signal meanwhile ends the loop below at once, with the summary
        conn = mavutil.mavlink_connection(device, baud=baud, source_system=args.system_id or 1,
                                          source_component=ESTIMATOR_COMPONENT, autoreconnect=True)  # fmt: skip
        resync_connection(conn)  # a corrupt frame (radio noise) no longer swallows the frames after it
        if key is not None:
            signing.configure_connection(conn, key)
            say("MAVLink 2 signing on: unsigned or wrongly signed frames are dropped")
        tlog = open(args.tlog, "wb") if args.tlog else None  # noqa: SIM115 - closed below
        try:
            return _loop(conn, core, args, say, every, interactive, stop, tlog)
        finally:
            conn.close()
            if tlog is not None:
                tlog.close()
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _loop(conn: Any, core: LiveCore, args: argparse.Namespace, say: Any, every: float, interactive: bool,
          stop: list[str], tlog: Any = None) -> int:  # fmt: skip
    say(f"connecting on {args.connect}")
    pub = Publisher(core, args.rate)
    wall0 = last_rx = last_hb = last_line = time.monotonic()
    sends_first = args.connect.startswith(("udpout", "tcp")) and not args.connect.startswith("tcpin")
    if sends_first:
        _heartbeat(conn)  # a udpout peer only learns our address from what we send
    t_request: float | None = None
    mag_setup: Px4MagSetup | None = None
    reason = ""
    while not stop:
        now = time.monotonic()
        if core.target is None and now - wall0 > args.connect_timeout:
            raise RuntimeError(f"no autopilot HEARTBEAT on {args.connect} within {args.connect_timeout:g} s")
        if t_request is not None and now >= t_request:
            request_rates(conn, core, args.request_rates, say)  # after 1 s of listening: what is missing
            t_request = None
            if args.px4_raw_compass and args.compass and core.autopilot_kind == MAV_AUTOPILOT_PX4:
                mag_setup = Px4MagSetup(core, say, rate_hz=args.px4_scaled_imu_hz,
                                        may_request=args.request_rates != "never")
                mag_setup.start(now)
        if mag_setup is not None:
            mag_setup.poll(conn, now)
        if now - last_hb >= 1.0 and (core.target is not None or sends_first):
            _heartbeat(conn)
            last_hb = now
        if every > 0 and now - last_line >= every and core.target is not None:
            last_line = now
            if interactive:
                sys.stderr.write("\r\x1b[K" + line(core, pub))
                sys.stderr.flush()
            else:
                say(line(core, pub))
        msg = conn.recv_match(blocking=True, timeout=0.2)
        if msg is None:
            if core.target is not None and args.link_timeout > 0 and time.monotonic() - last_rx > args.link_timeout:
                reason = f"link quiet for {args.link_timeout:g} s"
                break
            continue
        if not _authentic(conn, msg):
            continue  # with signing, unsigned frames (even PX4's allowlisted ones) are not used
        if msg.get_srcSystem() == conn.mav.srcSystem and msg.get_srcComponent() == ESTIMATOR_COMPONENT:
            continue  # our own frames, echoed by a forwarder
        last_rx = time.monotonic()
        if tlog is not None:
            _log_frame(tlog, msg)
        had_target = core.target is not None
        if mag_setup is not None:
            mag_setup.on_message(msg)
        core.handle(msg)
        for note in core.take_notes():
            say(note)
        if not had_target and core.target is not None:
            conn.mav.srcSystem = args.system_id or core.target[0]
            say(f"we are {conn.mav.srcSystem}:{ESTIMATOR_COMPONENT}")
            t_request = time.monotonic() + 1.0
        if args.publish and (wc := pub.due()) is not None:
            conn.mav.send(wc)
            pub.sent += 1
        if args.duration is not None and core.elapsed_s >= args.duration:
            reason = f"duration {args.duration:g} s reached"
            break
    if interactive and every > 0:
        sys.stderr.write("\r\x1b[K")
    s = summary(core, pub, stop[0] if stop else reason or "done")
    if conn.mav.signing.secret_key is not None:
        from wire import signing

        s["signing"] = signing.counts(conn.mav)  # counts only, never the key
    if args.json:
        print(json.dumps(s, allow_nan=False), flush=True)
    else:
        say(f"stopped ({s['stop_reason']}): {line(core, pub)}")
        if core.model_note:
            say(core.model_note)
    return 130 if stop and core.target is None else 0


def _log_frame(tlog: Any, msg: Any) -> None:
    """One message in the telemetry log format (8-byte big-endian UNIX time in us, then the frame); frames
    pymavlink could not parse whole (BAD_DATA, a message id the dialect does not know) are left out."""
    buf = bytes(msg.get_msgbuf())
    if buf[:1] in (b"\xfd", b"\xfe") and msg.get_type() != "BAD_DATA" and not msg.get_type().startswith("UNKNOWN"):
        tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + buf)


def _authentic(conn: Any, msg: Any) -> bool:
    """With signing on, only correctly signed frames are used (the allowlisted unsigned ones are not)."""
    from wire import signing

    return signing.is_authentic(msg, conn.mav.signing.secret_key is not None)


def _heartbeat(conn: Any) -> None:
    conn.mav.heartbeat_send(MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, 4)  # MAV_STATE_ACTIVE
