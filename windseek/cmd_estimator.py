"""``windseek estimator --connect URL``: the wind UKF as a MAVLink companion process, publishing WIND_COV.

Connects with pymavlink to an autopilot (``windseek sitl``, PX4, ArduPilot) over UDP, TCP or
serial, runs :class:`~estimator.ukf.WindEstimator` through
:class:`~estimator.mavlink_adapter.MavlinkWindAdapter` on the live telemetry and sends the
estimate back on the same link as WIND_COV (air-mass velocity NED, m/s; variances m^2/s^2),
as system = the autopilot's, component 191 (MAV_COMP_ID_ONBOARD_COMPUTER), with a 1 Hz
HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER). A router between the programs (mavlink-router,
``windseek sitl --forward``) passes it on to the mission and ground stations; PX4 forwards it
only to its other MAVLink instances (``MAV_X_FORWARD``), and MAVProxy only to its master, never
to its other outputs (README, "One serial link, several programs"). The filter pauses while the
autopilot reports the vehicle on the ground or landing (``estimator.ground_gate``).

Inputs: IMU HIL_SENSOR (every sample, windseek SITL) or HIGHRES_IMU (PX4; HIL_SENSOR wins when
both come), ATTITUDE_QUATERNION (or ATTITUDE), LOCAL_POSITION_NED velocity, ESC_STATUS rotor
speeds (or RAW_RPM). At start it asks the autopilot (SET_MESSAGE_INTERVAL) for those that are
not streaming yet (``--request-rates missing``, default).

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
import sys
import time
from typing import Any

import numpy as np

from estimator.ground_gate import GroundGate, withheld
from wire.jsonsafe import json_safe
from wire.names import ESTIMATOR_COMPONENT

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
ROTOR_MESSAGES = ("ESC_STATUS", "RAW_RPM", "ESC_INFO")
#: Message ids and the rate (Hz) asked for when an input is missing at start.
WANTED = {"imu": (("HIL_SENSOR", "HIGHRES_IMU"), 105, 100.0),
          "attitude": (("ATTITUDE_QUATERNION", "ATTITUDE"), 31, 50.0),
          "velocity": (("LOCAL_POSITION_NED",), 32, 30.0),
          "rotors": (("ESC_STATUS", "RAW_RPM"), 291, 50.0)}  # fmt: skip
INPUTS = frozenset({"HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU", "ATTITUDE_QUATERNION", "ATTITUDE",
                    "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT", "ESC_STATUS", "RAW_RPM",
                    "ESC_INFO"})  # fmt: skip
#: Per input group, the message types in order of preference (the best one streaming is used).
PREFERENCE = {"imu": ("HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU"),
              "attitude": ("ATTITUDE_QUATERNION", "ATTITUDE"),
              "velocity": ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT"),
              "rotors": ("ESC_STATUS", "RAW_RPM")}  # fmt: skip


def pymavlink_url(url: str) -> tuple[str, int]:
    """A MAVSDK-style URL to a pymavlink device string and baud rate (pymavlink forms pass through)."""
    for pre, rep in (("udpin://", "udpin:"), ("udpout://", "udpout:"), ("udp://", "udpin:"),
                     ("tcpout://", "tcp:"), ("tcp://", "tcp:"), ("tcpin://", "tcpin:")):  # fmt: skip
        if url.startswith(pre):
            return rep + url[len(pre):], 115200
    if url.startswith("serial://"):
        dev, sep, baud = url[len("serial://"):].rpartition(":")
        return (dev, int(baud)) if sep and baud.isdigit() else (url[len("serial://"):], 57600)
    if url.startswith("/dev/") or url.startswith("COM"):
        dev, sep, baud = url.rpartition(":")
        return (dev, int(baud)) if sep and baud.isdigit() else (url, 57600)
    if url.split(":", 1)[0] in ("udpin", "udpout", "udpbcast", "tcp", "tcpin"):
        return url, 115200
    raise ValueError(f"--connect {url!r}: expected udpin://HOST:PORT, udpout://HOST:PORT, tcpout://HOST:PORT, "
                     "tcpin://HOST:PORT or serial:///dev/DEVICE:BAUD")


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
    p.add_argument("--esc-order", choices=("sitl", "px4"), default="sitl",
                   help="ESC-to-rotor order: windseek SITL (identity) or PX4 quad-X")
    p.add_argument("--imu-average", type=int, default=1, metavar="N",
                   help="average N consecutive IMU samples per filter step (cost / N; default 1)")
    p.add_argument("--request-rates", choices=("missing", "always", "never"), default="missing",
                   help="SET_MESSAGE_INTERVAL for the inputs at start: those not streaming (default), all, none")
    p.add_argument("--ground-gate", action=argparse.BooleanOptionalAction, default=True,
                   help="pause the filter while the autopilot reports the vehicle on the ground or landing "
                   "(EXTENDED_SYS_STATE) "
                   "and replace a filter that flew at the next take-off (default on; estimator.ground_gate)")
    p.add_argument("--system-id", type=int, default=None, help="our MAVLink system id (default: the autopilot's)")
    p.add_argument("--esc-component", type=int, default=None, metavar="ID",
                   help="rotor speeds (ESC_STATUS, RAW_RPM, ESC_INFO) only from this MAVLink component (158 with "
                   "windseek sitl --px4, whose PX4 sends a placeholder ESC_STATUS of its own; default any)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds of vehicle time")
    p.add_argument("--link-timeout", type=float, default=10.0, metavar="S",
                   help="stop when nothing arrived for S wall seconds (0 = never; default 10)")
    p.add_argument("--connect-timeout", type=float, default=30.0, metavar="S",
                   help="wall seconds to wait for the autopilot's first HEARTBEAT (default 30)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    p.add_argument("--progress-every", type=float, default=None, metavar="S",
                   help="wall seconds between progress lines on stderr (default: a live line on a terminal, "
                   "every 10 s otherwise; 0 = none)")
    p.set_defaults(func=run)


class LiveEstimator:
    """The estimator on a pymavlink connection: input selection, IMU averaging, velocity ordering,
    WIND_COV publishing (see the module docstring)."""

    def __init__(self, args: argparse.Namespace) -> None:
        from estimator.mavlink_adapter import PX4_QUAD_X, SITL_ORDER, MavlinkWindAdapter
        from estimator.ukf import WindEstimator
        from vehicle.params import load_vehicle

        if args.imu_average < 1:
            raise ValueError(f"--imu-average {args.imu_average}: must be an integer >= 1")
        if not (math.isfinite(args.rate) and args.rate > 0):
            raise ValueError(f"--rate {args.rate}: must be > 0")
        self.args = args
        self._vehicle = load_vehicle(args.vehicle)
        self._make = lambda: WindEstimator(self._vehicle)
        self._adapter = lambda est: MavlinkWindAdapter(est, PX4_QUAD_X if args.esc_order == "px4" else SITL_ORDER)
        warm_up(self._make())
        self.est = self._make()
        self.adapter = self._adapter(self.est)
        #: MAV_LANDED_STATE from EXTENDED_SYS_STATE (None: not reported, the filter always runs).
        self.landed_state: int | None = None
        self.restarts = 0
        self._gate = GroundGate()
        self.imu_type: str | None = None
        self.seen: dict[str, int] = {}
        self.pending_vel: list[Any] = []
        self.imu_sum: list[np.ndarray] = []
        self.next_pub = 0.0
        self.published = 0
        self.t = math.nan
        self.t0 = math.nan
        self.stop = False
        self.reason = ""

    # ------------------------------------------------------------------ input
    def paused(self) -> bool:
        """True while the autopilot reports the vehicle on the ground or landing (and --ground-gate
        is on): the filter is paused (``estimator.ground_gate``)."""
        return self.args.ground_gate and withheld(self.landed_state)

    def _restart(self) -> None:
        """A fresh filter at the lift-off after a flight (``estimator.ground_gate``); the inputs
        chosen at the start (``choose_inputs``) carry over."""
        sources = dict(self.adapter.sources)
        self.est = self._make()
        self.adapter = self._adapter(self.est)
        self.adapter.sources.update(sources)
        self.pending_vel.clear()
        self.imu_sum.clear()
        self.restarts += 1

    def handle(self, msg: Any) -> None:
        mtype = msg.get_type()
        self.seen[mtype] = self.seen.get(mtype, 0) + 1
        if mtype == "EXTENDED_SYS_STATE":
            self.landed_state = int(msg.landed_state)
            return
        if mtype not in INPUTS:
            return
        action = self._gate.admit(self.paused())  # paused on the ground (estimator.ground_gate)
        if action == "pause":
            if mtype == self.imu_type:
                self.t = msg.time_usec * 1e-6
            return
        if action == "restart":
            self._restart()
        if self.imu_type is None:
            return  # the inputs are chosen after the start window (see choose_inputs)
        if mtype in ("HIL_SENSOR", "HIGHRES_IMU", "SCALED_IMU"):
            if mtype != self.imu_type:
                return
            t = msg.time_usec * 1e-6
            self.t = t if not math.isfinite(self.t) else max(self.t, t)
            if math.isnan(self.t0):
                self.t0 = t
            self._imu(msg)
        elif mtype == "LOCAL_POSITION_NED":
            self.pending_vel.append(msg)
        else:
            self.adapter.handle(msg)
        est_t = self.est.t
        pend = self.pending_vel
        # Velocities wait until the IMU has caught up with them (an autopilot sends its state
        # ahead of the raw samples of the same interval; fed early they would move the filter
        # past samples still to come). Not forever: 30 queued means no IMU is flowing.
        while pend and (est_t is None or pend[0].time_boot_ms * 1e-3 <= est_t + 1e-9 or len(pend) > 30):
            self.adapter.handle(pend.pop(0))

    def _imu(self, msg: Any) -> None:
        n = self.args.imu_average
        if n == 1 or msg.get_type() == "SCALED_IMU":
            self.adapter.handle(msg)
            return
        self.imu_sum.append(np.array([msg.xacc, msg.yacc, msg.zacc, msg.xgyro, msg.ygyro, msg.zgyro], dtype=float))
        if len(self.imu_sum) < n:
            return
        m = np.mean(self.imu_sum, axis=0)
        self.imu_sum.clear()
        self.adapter.counts[msg.get_type()] += 1
        self.est.imu(msg.time_usec * 1e-6, m[0:3], m[3:6])

    def choose_inputs(self) -> str | None:
        """Pick the preferred message of every input group among those seen so far; returns the IMU
        message once one is streaming (None: keep waiting). Groups not seen yet are claimed later by
        the adapter (first seen wins)."""
        for group, names in PREFERENCE.items():
            name = next((n for n in names if self.seen.get(n)), None)
            if name is None:
                continue
            if group == "imu":
                self.imu_type = name
            else:
                self.adapter.sources.setdefault(group, name)
        return self.imu_type

    # ------------------------------------------------------------------ output
    def due(self) -> bool:
        if self.paused() or self.est.t is None or not math.isfinite(self.t) or self.t < self.next_pub:
            return False
        self.next_pub = self.t + 1.0 / self.args.rate
        return True

    def summary(self) -> dict[str, Any]:
        e = self.est
        ready = e.t is not None
        w = e.wind_ned if ready else np.full(3, math.nan)
        sig = np.sqrt(np.maximum(np.diag(e.wind_cov), 0.0)) if ready else np.full(3, math.nan)
        from recording.sim_hook import wind_speed_from_deg

        speed, from_deg = wind_speed_from_deg(w) if ready else (math.nan, math.nan)
        d = {"vehicle_time_s": None if not math.isfinite(self.t) else round(self.t, 3),
             "duration_s": None if not math.isfinite(self.t - self.t0) else round(self.t - self.t0, 3),
             "wind_ned_m_s": [round(float(v), 3) for v in w], "sigma_ned_m_s": [round(float(v), 3) for v in sig],
             "speed_m_s": round(speed, 3), "from_deg": round(from_deg, 1), "wind_cov_published": self.published,
             "imu_message": self.imu_type, "inputs": dict(self.adapter.sources), "accepted": dict(e.accepted),
             "rejected": dict(e.rejected), "restarts": self.restarts, "stop_reason": self.reason}  # fmt: skip
        return json_safe(d)

    def line(self) -> str:
        e = self.est
        if self.paused():
            return f"t {self.t:7.1f} s  on the ground or landing: filter paused  WIND_COV sent {self.published}"
        if e.t is None:
            return f"waiting for inputs (seen: {', '.join(sorted(k for k in self.seen if k in INPUTS)) or 'none'})"
        w = e.wind_ned
        sig = np.sqrt(np.maximum(np.diag(e.wind_cov), 0.0))
        from recording.sim_hook import wind_speed_from_deg

        speed, from_deg = wind_speed_from_deg(w)
        return (f"t {self.t:7.1f} s  wind N {w[0]:+5.2f} E {w[1]:+5.2f} D {w[2]:+5.2f} m/s "
                f"(+-{sig[0]:.2f} {sig[1]:.2f} {sig[2]:.2f}) = {speed:4.1f} m/s from {from_deg:5.1f} deg  "
                f"WIND_COV sent {self.published}")  # fmt: skip


def warm_up(est: Any) -> None:
    """Run a throw-away filter for a few hovering samples, so the numba kernels are compiled (or loaded
    from the cache) before the first real sample: on a fresh machine that takes 15-25 s, which would
    otherwise stall the filter at take-off."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    est.set_attitude(0.0, q)
    est.set_rotor_speeds(0.0, np.full(4, 393.0))
    for i in range(1, 40):
        t = 0.004 * i
        est.imu(t, np.array([0.0, 0.0, -9.81]), np.zeros(3))
        if i % 10 == 0:
            est.set_attitude(t, q)
            est.gnss_velocity(t, np.zeros(3))


def _request_rates(conn: Any, live: LiveEstimator, target: tuple[int, int], mode: str, say: Any) -> None:
    if mode == "never":
        return
    for group, (names, msg_id, hz) in WANTED.items():
        if mode == "missing" and any(live.seen.get(n) for n in names):
            continue
        conn.mav.command_long_send(target[0], target[1], MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                   float(msg_id), 1e6 / hz, 0, 0, 0, 0, 0)  # fmt: skip
        say(f"requested {names[0]} at {hz:g} Hz ({group})")


def run(args: argparse.Namespace) -> int:
    from pymavlink import mavutil

    from wire.dialect import mavlink as dialect

    # The windseek dialect (common + ESC_INFO/ESC_STATUS) for every connection made below.
    mavutil.mavlink = dialect
    mavutil.current_dialect = "windseek"
    device, baud = pymavlink_url(args.connect)
    live = LiveEstimator(args)
    interactive = sys.stderr.isatty()
    every = args.progress_every if args.progress_every is not None else (0.5 if interactive else 10.0)

    def say(text: str) -> None:
        if interactive and every > 0:
            sys.stderr.write("\r\x1b[K")
        print(f"windseek estimator: {text}", file=sys.stderr, flush=True)

    def _stop(signum: int, frame: object) -> None:
        live.stop = True
        live.reason = signal.Signals(signum).name

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    conn = mavutil.mavlink_connection(device, baud=baud, source_system=args.system_id or 1,
                                      source_component=ESTIMATOR_COMPONENT, autoreconnect=True)  # fmt: skip
    conn.mav.robust_parsing = True
    try:
        return _loop(conn, live, args, say, every, interactive)
    finally:
        conn.close()
        for s, h in old.items():
            signal.signal(s, h)


def _loop(conn: Any, live: LiveEstimator, args: argparse.Namespace, say: Any, every: float,
          interactive: bool) -> int:  # fmt: skip
    say(f"connecting on {args.connect}")
    wall0 = time.monotonic()
    target: tuple[int, int] | None = None
    if args.connect.startswith(("udpout", "tcp")) and not args.connect.startswith("tcpin"):
        _heartbeat(conn)  # a udpout peer only learns our address from what we send
    while target is None:
        if live.stop:
            return 130
        msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        if msg is not None and msg.autopilot != MAV_AUTOPILOT_INVALID:
            target = (msg.get_srcSystem(), msg.get_srcComponent())
        elif time.monotonic() - wall0 > args.connect_timeout:
            raise RuntimeError(f"no autopilot HEARTBEAT on {args.connect} within {args.connect_timeout:g} s")
        elif args.connect.startswith("udpout") and msg is None:
            _heartbeat(conn)
    conn.mav.srcSystem = args.system_id or target[0]
    say(f"autopilot system {target[0]} component {target[1]}; we are {conn.mav.srcSystem}:{ESTIMATOR_COMPONENT}")
    # Start window: see what streams, pick the IMU message, ask for what is missing.
    t_end = time.monotonic() + 1.0
    while time.monotonic() < t_end and not live.stop:
        msg = conn.recv_match(blocking=True, timeout=0.1)
        if msg is not None and msg.get_type() != "BAD_DATA":
            live.handle(msg)
    _request_rates(conn, live, target, args.request_rates, say)
    last_rx = last_hb = last_line = time.monotonic()
    while not live.stop:
        now = time.monotonic()
        if live.imu_type is None and live.choose_inputs():
            src = ", ".join(f"{g} {n}" for g, n in live.adapter.sources.items())
            say(f"inputs: imu {live.imu_type}, {src}")
        if now - last_hb >= 1.0:
            _heartbeat(conn)
            last_hb = now
        if every > 0 and now - last_line >= every:
            last_line = now
            if interactive:
                sys.stderr.write("\r\x1b[K" + live.line())
                sys.stderr.flush()
            else:
                print(f"windseek estimator: {live.line()}", file=sys.stderr, flush=True)
        msg = conn.recv_match(blocking=True, timeout=0.2)
        if msg is None:
            if args.link_timeout > 0 and time.monotonic() - last_rx > args.link_timeout:
                live.reason = f"link quiet for {args.link_timeout:g} s"
                break
            continue
        if msg.get_type() == "BAD_DATA":
            continue
        if msg.get_srcSystem() == conn.mav.srcSystem and msg.get_srcComponent() == ESTIMATOR_COMPONENT:
            continue  # our own frames, echoed by a forwarder
        if args.esc_component is not None and msg.get_type() in ROTOR_MESSAGES \
                and msg.get_srcComponent() != args.esc_component:
            continue  # another component's rotor telemetry (PX4 SITL's placeholder ESC_STATUS)
        last_rx = time.monotonic()
        live.handle(msg)
        if args.publish and live.due():
            conn.mav.send(live.adapter.wind_cov())
            live.published += 1
        if args.duration is not None and math.isfinite(live.t - live.t0) and live.t - live.t0 >= args.duration:
            live.reason = f"duration {args.duration:g} s reached"
            break
    if interactive and every > 0:
        sys.stderr.write("\r\x1b[K")
    s = live.summary()
    if args.json:
        print(json.dumps(s, allow_nan=False), flush=True)
    else:
        say(f"stopped ({live.reason or 'done'}): {live.line()}")
    return 0


def _heartbeat(conn: Any) -> None:
    conn.mav.heartbeat_send(MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, 4)  # MAV_STATE_ACTIVE
