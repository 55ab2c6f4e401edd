"""``windseek review FILE [-o OUT.rrd]``: a flight log (.tlog or .ulg) to a Rerun recording, with the
wind estimator re-run offline on the recorded sensors.

Prints a summary: duration, messages per type, which message fed which estimator input, what
was missing and what that cost, the wind estimate's mean and standard deviation (m/s NED, and
speed + from-direction in degrees), the RMSE against the simulation truth when the log carries
it (project SITL logs) and the RMS difference to the autopilot's own wind estimate when it has
one. See :mod:`review.convert`.
"""

from __future__ import annotations

import argparse
import json

from review.convert import format_summary, review


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "review",
        help="convert a flight log (.tlog, .ulg) to a Rerun recording, re-running the wind estimator",
        description="Convert a MAVLink telemetry log (.tlog: PX4, ArduPilot, MAVProxy, QGroundControl, windseek) "
        "or a PX4 ULog (.ulg) into a Rerun recording with the live runs' layout, re-running the wind estimator "
        "offline on the recorded sensors, and say what was missing.",
    )
    p.add_argument("file", help="the log: .tlog or .ulg")
    p.add_argument("-o", "--out", default=None, help="output .rrd (default: next to the input, with .rrd)")
    p.add_argument("--vehicle", default="nasa-quad", help="vehicle file of the force model (default nasa-quad)")
    p.add_argument("--motor-order", choices=("auto", "windseek", "quad-x"), default="auto",
                   help="ESC/output number -> rotor: auto (windseek for logs with simulation truth, else quad-x)")
    p.add_argument("--rate", type=float, default=25.0, help="rate of the estimate and pose series, Hz (default 25)")
    p.add_argument("--settle", type=float, default=5.0,
                   help="seconds after each take-off left out of the figures (default 5)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not args.rate > 0:
        raise ValueError(f"--rate {args.rate}: must be > 0")
    res = review(args.file, args.out, vehicle=args.vehicle, motor_order=args.motor_order, rate_hz=args.rate,
                 settle_s=args.settle)  # fmt: skip
    print(json.dumps(res.summary) if args.json else format_summary(res.summary))
    return 0
