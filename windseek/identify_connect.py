"""``windseek identify --connect URL --vehicle BASE``: the identification flown on a PX4 through MAVLink.

The fitting manoeuvre and then the validation manoeuvre in one flight (:mod:`identify.fly.px4`: take-off,
hover, offboard attitude + thrust setpoints, hold, land), then the same estimation as the in-process route
(:func:`identify.pipeline.identify`) and the same vehicle file, with what the flight measured of the
accelerometer's noise in ``[model.info] accel_noise_m_s2`` (the estimator sizes its accelerometer noise with
it: :meth:`estimator.config.EstimatorConfig.for_vehicle`). An abort (geofence, floor, tilt, saturation,
link, offboard, Ctrl-C) lands the vehicle, is said in one line and in the JSON (``abort``), and the exit
code is 3; a completed fitting manoeuvre is still identified. As with ``--log``, terms the flight did not
excite are screened out (:func:`identify.excitation.screen`) and a model that cannot sense the wind is not
written without ``--partial`` (exit 1).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import signal
import sys
from pathlib import Path
from typing import Any

import numpy as np

from wire.jsonsafe import json_safe

#: Reference speeds of the PX4 route when not given (m/s): PX4 SIH's linear drag (1 N per m/s on 1 kg) needs
#: 17 deg of tilt at 3 m/s and 39 deg at the in-process route's 8 m/s. The climb is the in-process route's 2 m/s:
#: with 1 m/s, two of three 60 s flights on SIH gave a thrust model bent outside its narrow vertical domain
#: (a second hover solution near 5 m/s of descent through the air, which the estimator's filter found from its
#: cold start); with 2 m/s none of three did.
PX4_SPEED_M_S, PX4_CLIMB_M_S = 3.0, 2.0


def _range(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(",")
    try:
        r = (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected MIN,MAX, e.g. 1000,2000") from None
    if not (sep and math.isfinite(r[0]) and math.isfinite(r[1]) and r[1] > r[0]):
        raise argparse.ArgumentTypeError(f"{text!r}: expected MIN,MAX with MIN < MAX")
    return r


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of the ``--connect`` route (the shared ones, --vehicle, -o, --duration, --band, --speed,
    --climb, --plot, --json, are the command's)."""
    g = p.add_argument_group("flying on a PX4 through MAVLink (--connect)")
    g.add_argument("--connect", metavar="URL", help="fly the manoeuvres on a PX4 through MAVSDK instead of in "
                   "windseek's world: udpin://0.0.0.0:14540, udpout://HOST:PORT, serial:///dev/ttyUSB0:57600; "
                   "needs --vehicle (its mass, inertia, geometry, rotor speeds and PX4 output order)")
    g.add_argument("--altitude", type=float, default=10.0, help="take-off and manoeuvre altitude above home, m")
    g.add_argument("--fence", type=float, default=150.0, help="geofence: half-width of the box about the start, m")
    g.add_argument("--floor", type=float, default=3.0, help="lowest altitude above home in the manoeuvres, m")
    g.add_argument("--ceiling", type=float, default=40.0, help="highest altitude above home, m")
    g.add_argument("--tilt-limit", type=float, default=35.0, help="abort beyond this tilt from level, deg")
    g.add_argument("--setpoint-amplitudes", default="0.12,5,5,10", metavar="T,R,P,Y",
                   help="multisine peaks on the setpoint: collective thrust (fraction of the hover thrust), roll, "
                   "pitch, yaw (deg); see identify/fly/px4_setpoint.py (default 0.12,5,5,10)")
    g.add_argument("--speed-hint", type=float, default=1.0, metavar="K",
                   help="the simulator's speed factor (PX4_SIM_SPEED_FACTOR): PX4's loss timeouts are scaled by it")
    g.add_argument("--output-range", type=_range, default=(1000.0, 2000.0), metavar="MIN,MAX",
                   help="motor output values at zero and full command (PWM us; default 1000,2000)")
    g.add_argument("--esc-component", type=int, default=None, metavar="ID",
                   help="rotor speeds from ESC_STATUS of this component (158 with windseek sitl --px4; the "
                   "autopilot's own id for real ESC telemetry); default: the motor outputs through the motor map")
    g.add_argument("--esc-order", choices=("px4", "rotors"), default="px4",
                   help="how --esc-component numbers its ESCs: px4 (ESC i = PX4 output i, ESCs on PX4's outputs; "
                   "default) or rotors (ESC i = the vehicle file's rotor i: windseek sitl --px4's component 158)")
    g.add_argument("--max-clock-speed", type=float, default=6.0, metavar="K", help="refuse to fly, or abort the "
                   "manoeuvre, when the autopilot's clock runs faster than K x real time (a simulator in free-running "
                   "lockstep: the setpoints, paced by the wall clock, are then too coarse); 0: no check (default 6)")
    g.add_argument("--imu", choices=("highres", "scaled"), default="highres", help="IMU message: HIGHRES_IMU (PX4 "
                   "subtracts EKF2's accelerometer-bias estimate) or SCALED_IMU (the calibrated sensor; better on PX4 "
                   "SIH, which has no sensor bias while EKF2 estimates 0.1-0.3 m/s^2)")
    g.add_argument("--imu-rate", type=float, default=250.0, metavar="HZ", help="IMU message rate asked for")
    g.add_argument("--link-timeout", type=float, default=3.0, metavar="S", help="wall seconds without telemetry "
                   "that abort the flight (PX4's own failsafe then flies it)")
    g.add_argument("--dl-loss", type=float, default=5.0, metavar="S", help="PX4's data-link-loss timeout "
                   "(COM_DL_LOSS_T), wall seconds (times --speed-hint on the autopilot)")
    g.add_argument("--offboard-loss", type=float, default=1.0, metavar="S", help="PX4's offboard-loss timeout "
                   "(COM_OF_LOSS_T), wall seconds (times --speed-hint)")
    g.add_argument("--keep-params", action="store_true", help="leave the failsafe parameters as set for the flight "
                   "(default: restore the old values after the landing)")
    g.add_argument("--connect-timeout", type=float, default=30.0, metavar="S", help="wall seconds to wait for the "
                   "autopilot")


def _amplitudes(text: str) -> tuple[float, float, float, float]:
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 4 or not all(math.isfinite(x) for x in v):
        raise ValueError(f"--setpoint-amplitudes {text!r}: expected 4 numbers T,R,P,Y")
    if not (0.0 < v[0] <= 0.3 and all(0.0 < x <= 20.0 for x in v[1:])):
        raise ValueError(f"--setpoint-amplitudes {text!r}: thrust in (0, 0.3] of hover, angles in (0, 20] deg")
    return v[0], math.radians(v[1]), math.radians(v[2]), math.radians(v[3])


def accel_noise(data: Any) -> list[float]:
    """Per body axis (FRD), the accelerometer's noise in the record (m/s^2, 1-sigma per sample): the spread of
    the specific force about its 0.1 s running mean, over the samples used."""
    f = data.specific_force[data.mask]
    k = max(3, int(round(0.1 / max(float(np.median(np.diff(data.t))), 1e-4))))
    kernel = np.ones(k) / k
    smooth = np.stack([np.convolve(f[:, i], kernel, mode="same") for i in range(3)], axis=1)
    resid = (f - smooth)[k:-k]
    return [round(float(x) * math.sqrt(k / (k - 1.0)), 3) for x in resid.std(axis=0)]


def run_connect(args: argparse.Namespace) -> int:
    """The ``--connect`` route (see the module docstring); returns the exit code."""
    from identify.design import ManoeuvreSpec
    from identify.excitation import screen, wind_blind
    from identify.fly.px4 import Px4FlightConfig, fly_px4
    from identify.fly.px4_guard import GuardLimits
    from identify.pipeline import identify
    from identify.report import format_report, identified_vehicle, plot_fit
    from vehicle.vehicle_file import format_vehicle_file, load_vehicle

    if args.scenario:
        raise ValueError(f"give a SCENARIO ({args.scenario}) or --connect URL, not both")
    if not args.vehicle:
        raise ValueError("--connect needs --vehicle BASE: the vehicle flown (mass, inertia, geometry, rotors)")
    vehicle = load_vehicle(args.vehicle)
    try:
        band = tuple(float(x) for x in args.band.split(","))
    except ValueError:
        band = ()
    if len(band) != 2:
        raise ValueError(f"--band {args.band!r}: expected LOW,HIGH in Hz")
    common: dict[str, Any] = dict(band_hz=band, amplitudes=_amplitudes(args.setpoint_amplitudes),
                                  speed_m_s=PX4_SPEED_M_S if args.speed is None else args.speed,
                                  climb_m_s=PX4_CLIMB_M_S if args.climb is None else args.climb)  # fmt: skip
    fit_spec = ManoeuvreSpec(duration_s=args.duration, seed=0, **common)
    val_spec = ManoeuvreSpec(duration_s=args.validation_duration, seed=1, **common) if args.validation_duration > 0 \
        else None  # fmt: skip
    fit_spec.validate()
    if val_spec is not None:
        val_spec.validate()
    limits = GuardLimits(fence_m=args.fence, floor_m=args.floor, ceiling_m=args.ceiling, tilt_deg=args.tilt_limit,
                         link_timeout_s=args.link_timeout)  # fmt: skip
    limits.validate()
    if not (math.isfinite(args.speed_hint) and 0.1 <= args.speed_hint <= 50.0):
        raise ValueError(f"--speed-hint {args.speed_hint:g}: allowed range is [0.1, 50]")
    if not (math.isfinite(args.max_clock_speed) and args.max_clock_speed >= 0.0):
        raise ValueError(f"--max-clock-speed {args.max_clock_speed:g}: must be >= 0 (0: no check)")
    out = sys.stderr if args.json else sys.stdout

    def say(line: str) -> None:
        print(line, file=out, flush=True)

    stop: list[str] = []
    cfg = Px4FlightConfig(connect=args.connect, vehicle=vehicle, fitting=fit_spec, validation=val_spec,
                          altitude_m=args.altitude, limits=limits, speed_hint=args.speed_hint,
                          output_range=tuple(args.output_range), esc_component=args.esc_component,
                          esc_order=args.esc_order, max_clock_speed=args.max_clock_speed or None,
                          imu=f"{args.imu.upper()}_IMU", imu_rate_hz=args.imu_rate, dl_loss_s=args.dl_loss,
                          of_loss_s=args.offboard_loss,
                          restore_params=not args.keep_params, connect_timeout_s=args.connect_timeout, say=say,
                          stop=lambda: bool(stop))  # fmt: skip

    async def main() -> Any:
        loop = asyncio.get_running_loop()
        for s in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(s, stop.append, s.name)
        try:
            return await fly_px4(cfg)
        finally:
            for s in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(s)

    res = asyncio.run(main())
    abort = None if res.abort is None else {"cause": res.abort.cause, "message": res.abort.message}
    summary: dict[str, Any] = {"vehicle": vehicle.name, "connect": args.connect, "output": None, "abort": abort,
                               "flight": res.report}  # fmt: skip
    if res.fitting is None:
        say("no identification: the fitting manoeuvre was not flown to its end, or its record was not usable")
    else:
        ident = screen(identify(res.fitting, vehicle, res.validation), vehicle)
        blind = wind_blind(ident)
        noise = accel_noise(res.fitting)
        command = f"windseek identify --connect {args.connect} --vehicle {args.vehicle}"
        ident_v = identified_vehicle(vehicle, ident, command)
        ident_v.model_info["accel_noise_m_s2"] = noise
        if blind:  # as --log writes a partial model (windseek.identify_log)
            ident_v.model_info["warning"] = f"PARTIAL: this model cannot estimate the wind: {'; '.join(blind)}"
            summary["wind_blind"] = blind
            say(f"identify: the model cannot sense the wind: {'; '.join(blind)}" +
                ("" if args.partial else " (not written; --partial writes it)"))  # fmt: skip
        if args.output and (args.partial or not blind):
            header = (f"{vehicle.name}: Eq. 46 identified by `{command}`\n(flown on PX4 through MAVLink; the frame, "
                      "rotor and blade tables are the base file's, the [model] is the identification's)")
            Path(args.output).write_text(format_vehicle_file(ident_v, header))
            summary["output"] = args.output
        if args.plot and ident.data is not None:
            plot_fit(args.plot, ident, *ident.data)
        summary.update({"axes": ident.table(), "coefficients": ident.coefficients, "ci95": ident.ci95,
                        "domain": ident.domain, "accel_noise_m_s2": noise, "exclusions": list(ident.exclusions),
                        "validation": res.validation is not None})  # fmt: skip
        if not args.json:
            print(format_report(ident, vehicle.name))
            print(f"  accelerometer noise in the record (1-sigma per sample, FRD): {noise} m/s^2")
            if args.output:
                print(f"\nwrote {args.output}")
    if args.json:
        print(json.dumps(json_safe(summary), allow_nan=False), flush=True)
    if res.abort is not None:
        say(f"identify: the flight was aborted: {res.abort.line()}")
        return 3
    if res.fitting is None:
        return 3
    return 1 if summary.get("wind_blind") and not args.partial else 0
