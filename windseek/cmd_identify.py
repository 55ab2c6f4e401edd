"""``windseek identify``: the paper's system identification of Eq. 46, for any vehicle (see identify/): flown
in-process (SCENARIO), from a flight log (``--log``, :mod:`windseek.identify_log`), or flown on a PX4 through
MAVLink (``--connect``, :mod:`windseek.identify_connect`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from windseek import identify_connect, identify_log
from wire.jsonsafe import json_safe


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify",
        help="identify the wind estimator's force model (Eq. 46) for a vehicle and write its vehicle file",
        description="Fly the paper's identification manoeuvre (hover, then a 4-axis orthogonal multisine on the "
        "motors plus a low-frequency velocity and heading reference) and an independent validation manoeuvre, "
        "then choose the model structure by step-wise regression, estimate it by equation-error least squares, "
        "and write a vehicle file with the estimates, their 95 %% intervals, the fit and the identified domain. "
        "SCENARIO flies it in-process in windseek's world (its vehicle, its truth model, its wind: e.g. `calm`). "
        "--log FILE identifies from a flight log instead (PX4 ULog, MAVLink tlog or ArduPilot DataFlash), with "
        "--vehicle giving the known constants; the wind is then assumed zero. --connect URL --vehicle BASE flies "
        "it on a PX4 through MAVLink (identify/fly/px4.py).",
    )
    p.add_argument("scenario", nargs="?", help="scenario to fly the manoeuvres in (e.g. calm)")
    p.add_argument("--seed", type=int, default=1, help="world seed of the fitting flight (the validation flight "
                   "uses seed + 1000; default 1)")
    p.add_argument("-o", "--output", help="vehicle file to write (TOML)")
    p.add_argument("--vehicle", help="the vehicle flown (default: the scenario's); with --log, required: the vehicle "
                   "file of the airframe in the log (its mass, inertia, geometry, rotor limits and motor map are "
                   "taken as known)")
    p.add_argument("--duration", type=float, default=120.0, help="excitation length of the fitting manoeuvre, s")
    p.add_argument("--validation-duration", type=float, default=60.0, help="excitation length of the validation "
                   "manoeuvre, s")
    p.add_argument("--band", default="0.2,3.0", help="motor multisine band, Hz (low,high; default 0.2,3.0)")
    p.add_argument("--amplitudes", default="0.15,0.08,0.08,0.15", help="motor multisine peaks of delta_t, "
                   "delta_a, delta_e, delta_r as fractions of the hover delta_t")
    p.add_argument("--speed", type=float, default=None, help="peak of each horizontal velocity reference, m/s "
                   "(default 8; 3 with --connect)")
    p.add_argument("--climb", type=float, default=None, help="peak of the vertical velocity reference, m/s "
                   "(default 2)")
    p.add_argument("--plot", help="write measured vs modelled force and moment per axis (PNG)")
    p.add_argument("--json", action="store_true", help="print one JSON object: per axis R^2 %%, s^2, TIC and "
                   "NRMSE on the fitting and the validation manoeuvre")
    identify_log.add_arguments(p)
    identify_connect.add_arguments(p)
    p.set_defaults(func=run)


def _floats(text: str, n: int, what: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise ValueError(f"--{what} {text!r}: expected {n} comma-separated numbers") from None
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"--{what} {text!r}: expected {n} comma-separated finite numbers")
    return vals


def run(args: argparse.Namespace) -> int:
    from identify.design import ManoeuvreSpec, design
    from identify.fly.world import fly
    from identify.pipeline import identify
    from identify.report import format_report, identified_vehicle, plot_fit
    from sitl.scenario import load_scenario
    from vehicle.vehicle_file import format_vehicle_file, load_vehicle

    if args.scenario and args.log:
        raise ValueError(f"give a SCENARIO ({args.scenario}) or --log FILE ({args.log}), not both")
    if args.connect and args.log:
        raise ValueError(f"give --log FILE ({args.log}) or --connect URL ({args.connect}), not both")
    if args.log:
        return identify_log.run_log(args)
    if args.validation_log:
        raise ValueError("--validation-log needs --log FILE (a SCENARIO flies its own validation manoeuvre)")
    if args.connect:
        return identify_connect.run_connect(args)
    if not args.scenario:
        raise ValueError("give a SCENARIO to fly the manoeuvres in (e.g. `windseek identify calm -o my.toml`), or "
                         "--log FILE --vehicle BASE to identify from a flight log")
    scenario = load_scenario(args.scenario)
    vehicle = load_vehicle(args.vehicle or scenario.vehicle)
    band = _floats(args.band, 2, "band")
    amps = _floats(args.amplitudes, 4, "amplitudes")
    args.speed = 8.0 if args.speed is None else args.speed
    args.climb = 2.0 if args.climb is None else args.climb
    common = dict(band_hz=band, amplitudes=amps, speed_m_s=args.speed, climb_m_s=args.climb)
    fit_spec = ManoeuvreSpec(duration_s=args.duration, seed=0, **common)
    val_spec = ManoeuvreSpec(duration_s=args.validation_duration, seed=1, **common)
    hover_dt = vehicle.n_rotors * vehicle.control["hover_speed"] ** 2
    say = (lambda m: print(m, file=sys.stderr)) if args.json else print
    say(f"flying the fitting manoeuvre ({fit_spec.hover_s:g} s hover + {fit_spec.duration_s:g} s) in "
        f"{scenario.name}, seed {args.seed}, truth {vehicle.truth} ...")
    fit_data = fly(scenario, args.seed, design(fit_spec, hover_dt), vehicle)
    say(f"flying the validation manoeuvre ({val_spec.duration_s:g} s), seed {args.seed + 1000} ...")
    val_data = fly(scenario, args.seed + 1000, design(val_spec, hover_dt), vehicle)
    ident = identify(fit_data, vehicle, val_data)
    command = f"windseek identify {scenario.name} --seed {args.seed}" + (f" --vehicle {args.vehicle}" if args.vehicle
                                                                          else "")
    out = identified_vehicle(vehicle, ident, command)
    if args.output:
        header = (f"{vehicle.name}: Eq. 46 identified by `{command}`\n(truth {vehicle.truth}; the frame, rotor "
                  "and blade tables are the flown vehicle's, the [model] is the identification's)")
        Path(args.output).write_text(format_vehicle_file(out, header))
    if args.plot and ident.data is not None:
        plot_fit(args.plot, ident, *ident.data)
    if args.json:
        print(json.dumps(json_safe({"vehicle": vehicle.name, "truth": vehicle.truth, "scenario": scenario.name,
                                    "seed": args.seed, "output": args.output, "axes": ident.table(),
                                    "coefficients": ident.coefficients, "ci95": ident.ci95,
                                    "domain": ident.domain}), allow_nan=False))  # fmt: skip
    else:
        print(format_report(ident, vehicle.name))
        if args.output:
            print(f"\nwrote {args.output}")
    return 0
