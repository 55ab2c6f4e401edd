"""``windseek identify --log FILE --vehicle BASE``: the identification from a flight log (identify/logs.py).

The vehicle file BASE gives what is known (mass, inertia, geometry, rotor inertia and limits, motor
map); the log gives the flight. Without ``--validation-log`` the last 30 % of the airborne record is
held out as the validation manoeuvre and the first 70 % is fitted (a record too short for that is
fitted whole, without validation metrics). The terms the flight did not excite are screened out
(:mod:`identify.excitation`). When the result cannot sense the wind (no airspeed force term in X or Y,
or no thrust), no vehicle file is written and the exit status is 1, unless ``--partial`` asks for the
file anyway (its ``[model.info] warning`` says what it lacks).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vehicle.params import COEFFICIENT_NAMES
from wire.jsonsafe import json_safe

if TYPE_CHECKING:
    from identify.flight_data import FlightData
    from identify.pipeline import Identification
    from vehicle.params import VehicleParams

#: Share of the airborne record held out for validation when no validation log is given.
HOLDOUT = 0.3


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of the log mode (``windseek identify --log``)."""
    g = p.add_argument_group("from a flight log (instead of SCENARIO)")
    g.add_argument("--log", help="flight log to identify from: PX4 ULog (.ulg), MAVLink telemetry log (.tlog) or "
                   "ArduPilot DataFlash log (.bin); needs --vehicle (the vehicle file of the airframe flown)")
    g.add_argument("--validation-log", help="an independent validation manoeuvre's log (default: the last 30 %% "
                   "of the --log airborne record is held out, the first 70 %% fitted)")
    g.add_argument("--window", help="START,END: use only this part of the --log (s from the log's start, as on "
                   "`windseek review`'s timeline; default: the whole airborne record)")
    g.add_argument("--motor-order", default="vehicle", choices=("vehicle", "quad-x", "windseek"),
                   help="which ESC / actuator output drives which rotor (default: the vehicle file's px4_outputs)")
    g.add_argument("--output-map", default="px4", choices=("px4", "sitl"), help="actuator outputs (PWM 1000-2000 "
                   "us) to rotor speeds: px4 = the vehicle's idle..max speed, sitl = 0..max (default px4)")
    g.add_argument("--thr-mdl-fac", type=float, help="PX4 THR_MDL_FAC of the vehicle (default: speed linear in "
                   "the output)")
    g.add_argument("--min-height", type=float, default=1.0, help="samples less than this above the ground "
                   "level are excluded as ground contact / ground effect, m (default 1)")
    g.add_argument("--partial", action="store_true", help="write the vehicle file even when the identified model "
                   "cannot sense the wind (marked as partial in [model.info]); without it such a model is not "
                   "written and the exit status is 1")


def run_log(args: argparse.Namespace) -> int:
    """The log mode of ``windseek identify`` (see the module docstring)."""
    from identify.excitation import screen, wind_blind
    from identify.pipeline import identify
    from identify.report import plot_fit
    from vehicle.vehicle_file import load_vehicle

    if not args.vehicle:
        raise ValueError("--log needs --vehicle BASE: the vehicle file of the airframe flown (mass, inertia, "
                         "geometry, rotor limits, motor map)")  # fmt: skip
    vehicle = load_vehicle(args.vehicle)
    say = (lambda m: print(m, file=sys.stderr)) if args.json else print
    fit, val, notes = _flights(args, vehicle)
    for n in notes:
        say(f"  {n}")
    ident = screen(identify(fit, vehicle, val), vehicle)
    blind = wind_blind(ident)
    refused = ""
    if blind and not args.partial:
        refused = (f"not written: the flight did not identify what a wind estimate needs ({'; '.join(blind)}): fly "
                   "the identification manoeuvre (`windseek identify --help`), or give --partial")
    if args.output and not refused:
        _write(args, vehicle, ident, blind, notes)
    if args.plot and ident.data is not None:
        plot_fit(args.plot, ident, *ident.data)
    _print(args, vehicle, ident, blind, refused, notes)
    if refused:
        print(f"windseek identify: {refused}", file=sys.stderr)
        return 1
    return 0


def _flights(args: argparse.Namespace, vehicle: VehicleParams) -> tuple[FlightData, FlightData | None, list[str]]:
    """(fitting data, validation data or None, notes) from --log and --validation-log or the hold-out."""
    from identify.logs import read_log, split_record

    options: dict[str, Any] = dict(motor_order=args.motor_order, output_profile=args.output_map,
                                   thr_mdl_fac=args.thr_mdl_fac, min_height_m=args.min_height)  # fmt: skip
    flight = read_log(args.log, vehicle, window=_window(args.window), **options)
    notes = [f"{Path(args.log).name}: {n}" for n in flight.notes]
    if not args.validation_log:
        fit, val, how = split_record(flight.data, HOLDOUT)
        return fit, val, [*notes, how]
    val_flight = read_log(args.validation_log, vehicle, **options)
    notes += [f"{Path(args.validation_log).name}: {n}" for n in val_flight.notes]
    return flight.data, val_flight.data, [*notes, f"validation: {args.validation_log}"]


def _window(text: str | None) -> tuple[float, float] | None:
    if not text:
        return None
    try:
        a, b = (float(x) for x in text.split(","))
    except ValueError:
        raise ValueError(f"--window {text!r}: expected START,END in seconds (e.g. 20,140)") from None
    if not a < b:
        raise ValueError(f"--window {text!r}: START must be before END")
    return a, b


def _command(args: argparse.Namespace) -> str:
    val = f" --validation-log {args.validation_log}" if args.validation_log else ""
    win = f" --window {args.window}" if args.window else ""
    return f"windseek identify --log {args.log} --vehicle {args.vehicle}{win}{val}"


def _write(args: argparse.Namespace, vehicle: VehicleParams, ident: Identification, blind: list[str],
           notes: list[str]) -> None:  # fmt: skip
    """The identified vehicle file (BASE with the identified [model]); a partial one says so twice."""
    from identify.report import identified_vehicle
    from vehicle.vehicle_file import format_vehicle_file

    out = identified_vehicle(vehicle, ident, _command(args))
    info = {**out.model_info, "notes": notes}
    header = (f"{vehicle.name}: Eq. 46 identified from the flight log {Path(args.log).name} by `{_command(args)}`\n"
              f"(known constants and the frame, rotor and blade tables are {vehicle.name}'s; the [model] is the "
              "identification's; wind assumed zero)")
    if blind:
        info["warning"] = f"PARTIAL: this model cannot estimate the wind: {'; '.join(blind)}"
        header += f"\nWARNING: PARTIAL model, it cannot estimate the wind: {'; '.join(blind)}"
    Path(args.output).write_text(format_vehicle_file(replace(out, model_info=info), header))


def summary_line(ident: Identification) -> str:
    """What was identified, in one line: the terms, and the axes left with none."""
    empty = [a.upper() for a, r in ident.axes.items() if not r.names]
    line = f"identified: {len(ident.coefficients)} of {len(COEFFICIENT_NAMES)} terms"
    if len(ident.coefficients) <= 6:
        line += f" ({', '.join(ident.coefficients) or 'none'})"
    if empty:
        line += f"; axes with no term: {', '.join(empty)} (their metrics are those of a zero model)"
    return line


def _print(args: argparse.Namespace, vehicle: VehicleParams, ident: Identification, blind: list[str], refused: str,
           notes: list[str]) -> None:  # fmt: skip
    from identify.excitation import spans
    from identify.report import format_report

    excitation = spans(ident.data[0], vehicle) if ident.data is not None else {}
    if args.json:
        print(json.dumps(json_safe({
            "vehicle": vehicle.name, "log": args.log, "validation_log": args.validation_log, "output": args.output,
            "written": bool(args.output) and not refused, "refused": refused or None, "wind_blind": blind,
            "summary": summary_line(ident), "axes": ident.table(), "coefficients": ident.coefficients,
            "ci95": ident.ci95, "not_identified": {a: r.not_identified for a, r in ident.axes.items()},
            "excitation": excitation, "exclusions": list(ident.exclusions), "notes": notes,
            "domain": ident.domain}), allow_nan=False))  # fmt: skip
        return
    print(format_report(ident, vehicle.name))
    print("\nexcitation (5th-95th percentile span over the fit; identify/excitation.py says what each term needs):")
    print("  " + ", ".join(f"{k} {v:.3g}" for k, v in excitation.items()))
    print(f"\n{summary_line(ident)}")
    if blind:
        print(f"WARNING: this model cannot estimate the wind: {'; '.join(blind)}")
    if args.output and not refused:
        print(f"\nwrote {args.output}" + (" (PARTIAL, see [model.info] warning)" if blind else ""))
