"""``windseek review FILE [-o OUT.rrd]``: a flight log (.tlog, .ulg or ArduPilot .bin) to a Rerun
recording, with the wind estimator re-run offline on the recorded sensors.

Prints a summary: duration and airborne time, messages per type, which message fed which estimator
input, what was missing and what that cost, the wind estimate's mean and standard deviation (m/s NED,
and speed + from-direction in degrees) over the trusted samples, or no figure and why, the RMSE
against the simulation truth when the log carries it and the comparison with the autopilot's own
wind estimate when it has one. See :mod:`review.convert`.

Exit status: 0 when the review was done; 1 when the log held nothing usable (a truncated or corrupt
file); 2 on bad input (no such file, a directory, not a log). Problems go to stderr, one line each;
with ``--json`` stdout is always one JSON object (``{"file", "error"}`` on failure).
"""

from __future__ import annotations

import argparse
import json
import sys


def _imu_rate(text: str) -> float | None:
    if text == "auto":
        return None
    if text == "full":
        return 0.0
    v = float(text)
    if not v >= 0.0:
        raise argparse.ArgumentTypeError(f"{text}: must be auto, full or a rate >= 0 Hz")
    return v


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "review",
        help="convert a flight log (.tlog, .ulg, .bin) to a Rerun recording, re-running the wind estimator",
        description="Convert a MAVLink telemetry log (.tlog: PX4, ArduPilot, MAVProxy, QGroundControl, windseek), "
        "a PX4 ULog (.ulg) or an ArduPilot DataFlash log (.bin) into a Rerun recording with the live runs' layout, "
        "re-running the wind estimator offline on the recorded sensors, and say what was missing and what the "
        "figures can be trusted for. The kind of log is recognised by its content.",
    )
    p.add_argument("file", help="the log: .tlog, .ulg or .bin")
    p.add_argument("-o", "--out", default=None, help="output .rrd (default: next to the input, with .rrd)")
    p.add_argument("--vehicle", default="nasa-quad", help="vehicle file of the force model (default nasa-quad)")
    p.add_argument("--motor-order", choices=("auto", "windseek", "quad-x"), default="auto",
                   help="ESC/output number -> rotor: auto (windseek for logs with simulation truth, else quad-x)")
    p.add_argument("--rate", type=float, default=25.0, help="rate of the estimate and pose series, Hz (default 25)")
    p.add_argument("--settle", type=float, default=5.0,
                   help="seconds after each take-off whose estimate is not trusted (default 5)")
    p.add_argument("--imu-rate", type=_imu_rate, default=None, metavar="auto|full|HZ",
                   help="IMU rate fed to the estimator: auto (decimated only on long logs, default), full, or Hz")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from review.convert import review
    from review.progress import NoProgress, Stages
    from review.summary import format_summary
    from wire.jsonsafe import json_safe

    if not args.rate > 0:
        raise ValueError(f"--rate {args.rate}: must be > 0")
    show = not args.json and sys.stderr.isatty()
    try:
        with Stages(f"reviewing {args.file}") if show else NoProgress() as progress:
            res = review(args.file, args.out, vehicle=args.vehicle, motor_order=args.motor_order, rate_hz=args.rate,
                         settle_s=args.settle, imu_rate_hz=args.imu_rate, progress=progress)  # fmt: skip
    except (OSError, ValueError) as e:
        if not args.json:
            raise
        print(f"windseek review: error: {e}", file=sys.stderr)
        print(json.dumps({"file": args.file, "error": str(e)}))
        return 2
    s = res.summary
    for w in s.get("warnings", []):
        print(f"windseek review: warning: {args.file}: {w}", file=sys.stderr)
    if not res.usable:
        print(f"windseek review: error: {args.file}: {s['error']}", file=sys.stderr)
    print(json.dumps(json_safe(s), allow_nan=False) if args.json else format_summary(s))
    return 0 if res.usable else 1
