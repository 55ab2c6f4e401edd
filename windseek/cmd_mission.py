"""``windseek mission --connect URL --strategy NAME``: fly a source search through MAVSDK.

Connects to an autopilot (``windseek sitl``, PX4) over UDP, TCP or serial, runs the wind
estimator live on the telemetry, flies the strategy in offboard mode inside a geofence box,
altitude band and time limit, lands at the declared source and prints a summary (``--json``:
one JSON object). Exit status: 0 declared and landed, 1 stopped by a safety rule (the cause is
printed as one ``ABORT (cause): why`` line and in the JSON), 2 could not start. ``--rrd PATH``
records the mission's side (:mod:`recording.mission_rrd`: the strategy's posterior, setpoints, states).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
from dataclasses import replace
from typing import TYPE_CHECKING

from mission.safety import SafetyLimits
from mission.strategies import STRATEGIES
from mission.wind_modes import LIVE_WIND_MODES

if TYPE_CHECKING:
    from mission.result import MissionResult


def add_parser(sub: argparse._SubParsersAction) -> None:
    d = SafetyLimits()
    p = sub.add_parser(
        "mission",
        help="fly a source search on an autopilot through MAVSDK (estimator live, safety supervisor)",
        description="Fly a source-seeking strategy on a MAVLink autopilot (windseek sitl or PX4) through "
        "MAVSDK: arm, take off, search in offboard mode with the live wind estimator, land at the declared "
        "source. Geofence box, altitude limits, time limit; on a link loss, an estimator fault or an offboard "
        "rejection the vehicle holds and lands and the reason is printed.",
    )
    p.add_argument("--connect", required=True, metavar="URL",
                   help="MAVSDK connection: udpin://0.0.0.0:14540, udpout://HOST:PORT, tcpout://HOST:PORT, "
                   "serial:///dev/ttyUSB0:57600")
    p.add_argument("--strategy", required=True, choices=sorted(STRATEGIES), help="search strategy")
    p.add_argument("--wind", default="estimated", choices=LIVE_WIND_MODES,
                   help="wind information: the live UKF on the telemetry (default), WIND_COV from the network "
                   "(mavlink), or none")
    p.add_argument("--params", default=None, help="strategy file (TOML with a [strategy] table)")
    p.add_argument("--altitude", type=float, default=None, help="search altitude above home, m (default: the "
                   "strategy's)")
    p.add_argument("--geofence", default=None, metavar="N,E,D,N,E,D",
                   help="geofence box corners relative to home, m NED (default "
                   f"{','.join(f'{v:g}' for v in d.box_min_ned + d.box_max_ned)})")
    p.add_argument("--min-altitude", type=float, default=d.min_altitude_m, help="lowest search altitude, m")
    p.add_argument("--max-altitude", type=float, default=d.max_altitude_m, help="highest altitude, m")
    p.add_argument("--time-limit", type=float, default=d.time_limit_s, help="mission time limit, vehicle s")
    p.add_argument("--link-timeout", type=float, default=d.link_timeout_s,
                   help="wall seconds without telemetry that count as a link loss")
    p.add_argument("--speed-hint", type=float, default=1.0, help="the simulator's speed factor, if any "
                   "(scales the wall-clock waits)")
    p.add_argument("--seed", type=int, default=0, help="seed of the strategy's randomized choices")
    p.add_argument("--vehicle", default="nasa_quad", help="vehicle file of the estimator's force model")
    p.add_argument("--signing-key", metavar="FILE", default=None,
                   help="MAVLink 2 signing: FILE holds the 32-byte key as 64 hex characters (default: "
                   "$WINDSEEK_SIGNING_KEY if set); MAVSDK has no signing, so the link runs through an "
                   "in-process signing bridge")
    p.add_argument("--esc-component", type=int, default=None, metavar="ID",
                   help="--wind estimated: rotor speeds (ESC_STATUS) from this MAVLink component of the vehicle (158 "
                   "with windseek sitl --px4, whose PX4 sends a placeholder ESC_STATUS of its own; default: the "
                   "autopilot's own)")
    p.add_argument("--buildings", default=None, metavar="SCENARIO",
                   help="fly among the [urban] buildings of this scenario (name or file): uploaded to the autopilot "
                   "as geofence exclusion zones and kept clear of by every setpoint")
    p.add_argument("--rrd", default=None, metavar="PATH",
                   help="a Rerun recording of the mission's side: the strategy's source posterior and credible "
                   "region (1 Hz), the setpoints sent, the strategy states, the path as the mission reads it "
                   "(recording/mission_rrd.py)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout (lines go to stderr)")
    p.set_defaults(func=run)


def result_line(res: MissionResult) -> str:
    """The mission's one-line outcome: cause, declared source (m NED), time from arming to the declaration
    (s; "no declaration" without one, where the time would be NaN), path (m), final state."""
    d = res.declared_ned
    where = f"N {d[0]:.1f} E {d[1]:.1f} D {d[2]:.1f} m" if d else "none"
    if d and math.isfinite(res.credible_radius_m):
        where += f", 90 % within {res.credible_radius_m:.1f} m"
    when = f"time {res.time_s:.1f} s" if math.isfinite(res.time_s) else "time: no declaration"
    return (f"{res.strategy} with {res.wind} wind: cause {res.cause}; declared source {where} "
            f"(confidence {res.confidence:.2f}); {when}; path {res.path_m:.1f} m; "
            f"landed {res.landed}, disarmed {res.disarmed}")  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from mission.runners.mavsdk_runner import MissionConfig, run_mission
    from mission.strategies.params import load_params
    from wire.signing import load_key

    key = load_key(args.signing_key)  # a bad key: one clear line, before any connection
    buildings = None
    if args.buildings is not None:
        from mission.runners.fence import SiteBuildings

        try:
            buildings = SiteBuildings.from_scenario_file(args.buildings)
        except (OSError, ValueError) as e:
            raise ValueError(f"--buildings {args.buildings}: {e}") from None

    limits = replace(SafetyLimits(), min_altitude_m=args.min_altitude, max_altitude_m=args.max_altitude,
                     time_limit_s=args.time_limit, link_timeout_s=args.link_timeout)  # fmt: skip
    if args.geofence:
        lo, hi = SafetyLimits.box_from_text(args.geofence)
        limits = replace(limits, box_min_ned=lo, box_max_ned=hi)
    limits.validate()
    alt = args.altitude
    if alt is not None and not (math.isfinite(alt) and 0.0 < alt <= limits.max_altitude_m):
        raise ValueError(f"--altitude {args.altitude:g}: the search altitude above home must be in "
                         f"(0, {limits.max_altitude_m:g}] m (--max-altitude)")  # fmt: skip
    out = sys.stderr if args.json else sys.stdout

    def say(line: str) -> None:
        print(line, file=out, flush=True)

    cfg = MissionConfig(
        connect=args.connect, strategy=args.strategy, params=load_params(args.strategy, args.params),
        altitude_m=args.altitude, wind=args.wind, limits=limits, vehicle=args.vehicle, seed=args.seed,
        speed_hint=args.speed_hint, esc_component=args.esc_component, say=say, signing_key=key,
        buildings=buildings,
    )  # fmt: skip
    recorder = None
    if args.rrd is not None:
        from recording.mission_rrd import MissionRecorder

        recorder = MissionRecorder(args.rrd, strategy=args.strategy, seed=args.seed, scenario=args.buildings)
        cfg.observe = recorder.attach
    res: MissionResult | None = None
    try:
        res = asyncio.run(run_mission(cfg))
    finally:
        if recorder is not None:
            try:
                recorder.close(res)
            except Exception as e:  # noqa: BLE001 - after the flight: the result still gets printed
                say(f"mission: the recording {args.rrd} could not be closed: {e}")
    if args.json:
        print(json.dumps(res.to_dict(), allow_nan=False))
    else:
        print(result_line(res))
        for r in res.reasons:
            print(f"  {r}")
    return 0 if res.cause == "declared" and res.disarmed else 1
