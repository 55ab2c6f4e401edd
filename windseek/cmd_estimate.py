"""``windseek estimate SCENARIO``: simulator + wind estimator in lockstep, with accuracy figures.

Figures (see ``estimator.metrics``): RMSE per axis N, E, D (m/s) of the instantaneous
estimate against the true total wind and of 1-s averages, horizontal RMSE, direction RMSE
(deg), 2-sigma coverage, re-convergence after the scenario's wind steps (s), the
estimator's cost per IMU step (us, predict + updates + outputs), and the final force-scale
estimate (dimensionless) next to the model/true mass ratio it should approach.

The estimator's force model is the scenario vehicle's own vehicle file's [model] (for the built-in
vehicles: identified by ``windseek identify`` on their blade-element truth), or ``--vehicle FILE``'s.
Estimator preset (``--calibration``, see ``EstimatorConfig``): by default the one the model's vehicle
file calls for (``calibrated`` when it was identified, as the paper assumes; ``uncalibrated``, with a
force-scale state, otherwise), and ``uncalibrated`` with ``--perturb-model``. The JSON says which truth
the world flew and which model the estimator used.
"""

from __future__ import annotations

import argparse
import json
import time

from estimator.config import preset_for
from estimator.metrics import accuracy
from estimator.ukf import PRESETS, EstimatorConfig
from mission.runners.estimator_run import InProcessRunner
from sitl.scenario import load_scenario
from vehicle.vehicle_file import load_vehicle


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "estimate",
        help="run a scenario with the wind estimator in lockstep and print its accuracy",
        description="Fly a scenario (built-in name such as paper-s1, or a .toml path) with the wind UKF fed "
        "from the simulated sensors, and print its accuracy against the true wind.",
    )
    p.add_argument("scenario", help="built-in scenario name or path to a scenario .toml")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds (default: the scenario's)")
    p.add_argument(
        "--perturb-model",
        action="store_true",
        help="estimator model parameters drawn inside the paper's 95%% intervals, mass +-5%%, inertia +-10%%",
    )
    p.add_argument("--no-rpm", action="store_true", help="no ESC telemetry: rotor speeds implied by motor commands")
    p.add_argument(
        "--calibration",
        choices=PRESETS,
        default=None,
        help="estimator preset: 'calibrated' = mass and force model identified (no force-scale state, z accel bias "
        "state), 'uncalibrated' = force-scale state for a model known to a few %% (default: the one the model's "
        "vehicle file calls for, uncalibrated with --perturb-model)",
    )
    p.add_argument("--vehicle", default=None, help="vehicle file (name or path) of the estimator's force model, e.g. "
                   "one written by `windseek identify` (default: the scenario vehicle's own)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def default_calibration(perturb_model: bool) -> str:
    """Preset for a simulated run: the exact model is an identified vehicle, a perturbed one is not."""
    return "uncalibrated" if perturb_model else "calibrated"


def estimate(
    scenario_name: str,
    seed: int | None = None,
    duration: float | None = None,
    perturb_model: bool = False,
    no_rpm: bool = False,
    calibration: str | None = None,
    vehicle: str | None = None,
) -> dict:
    """Run one scenario with the estimator and return the summary dictionary.

    ``calibration``: estimator preset name (``PRESETS``); None = the preset the model's vehicle file calls for
    (:meth:`EstimatorConfig.for_vehicle`), ``uncalibrated`` with a perturbed model. ``vehicle``: the vehicle
    file of the estimator's force model (default: the world vehicle's own).
    """
    sc = load_scenario(scenario_name)
    if duration is not None:
        sc = sc.with_duration(duration)
    model = load_vehicle(vehicle) if vehicle else None
    if calibration is None:
        calibration = "uncalibrated" if perturb_model else preset_for(model or load_vehicle(sc.vehicle))
    config = EstimatorConfig.preset(calibration)
    runner = InProcessRunner(sc, seed=seed, perturb_model=perturb_model, no_rpm=no_rpm, config=config, model=model)
    t0 = time.perf_counter()
    log = runner.run()
    wall = time.perf_counter() - t0
    steps = tuple(c.t_s for c in sc.wind.changes if 0.0 < c.t_s < sc.duration_s)
    acc = accuracy(log.t, log.wind_est, log.wind_sigma, log.wind_true, log.direction_filtered_deg, step_times=steps)
    out: dict[str, object] = {
        "scenario": sc.name,
        "seed": runner.sim.seed,
        "perturb_model": perturb_model,
        "no_rpm": no_rpm,
        "calibration": calibration,
        "world_truth": f"{runner.sim.vehicle.name}: {runner.sim.vehicle.truth}",
        "estimator_model": f"{runner.params.model_name}: {runner.params.model_info.get('source', 'its vehicle file')}",
        "sim_time_s": round(runner.sim.t, 3),
        "wall_time_s": round(wall, 3),
    }
    out.update(acc.as_dict())
    out["us_per_step"] = round(log.us_per_step, 1)
    out["rejected"] = log.rejected
    s, s_sig = runner.estimator.force_scale
    out["force_scale"] = {"estimate": round(s, 5), "sigma": round(s_sig, 5)}
    b, b_sig = runner.estimator.accel_bias
    rnd = lambda a: [round(float(v), 4) for v in a]  # noqa: E731
    out["accel_bias_frd_m_s2"] = {"estimate": rnd(b), "sigma": rnd(b_sig)}
    out["model_force_ratio"] = round(runner.params.mass_kg / runner.sim.vehicle.mass_kg, 5)  # m_model / m_true
    out["final_wind_ned_ms"] = [round(float(v), 3) for v in log.wind_est[-1]] if len(log.t) else None
    return out


def run(args: argparse.Namespace) -> int:
    out = estimate(args.scenario, args.seed, args.duration, args.perturb_model, args.no_rpm, args.calibration,
                   args.vehicle)
    if args.json:
        print(json.dumps(out))
        return 0
    model = "perturbed model" if out["perturb_model"] else "model"
    rpm = "rotor speeds from motor commands" if out["no_rpm"] else "ESC rotor speeds"
    print(f"scenario {out['scenario']} (seed {out['seed']}), {rpm}, estimator preset {out['calibration']}")
    print(f"  world: {out['world_truth']}; estimator {model}: {out['estimator_model']}")
    r, ra = out["rmse_ms"], out["rmse_avg_ms"]
    print(f"  RMSE vs total wind   N {r['N']:.3f}  E {r['E']:.3f}  D {r['D']:.3f} m/s  "
          f"(horizontal {out['rmse_horizontal_ms']:.3f})")
    print(f"  RMSE of 1-s averages N {ra['N']:.3f}  E {ra['E']:.3f}  D {ra['D']:.3f} m/s  "
          f"(horizontal {out['rmse_horizontal_avg_ms']:.3f})")
    print(f"  direction RMSE {out['direction_rmse_deg']:.2f} deg "
          f"(Butterworth-filtered {out['direction_filtered_rmse_deg']:.2f})")
    print(f"  2-sigma coverage {100 * out['coverage_2sigma']:.1f} %  (N/E/D {out['coverage_2sigma_axis']})")
    if out["reconverge_s"] is not None:
        print(f"  re-convergence after the wind step: {out['reconverge_s']:.2f} s")
    print(f"  estimator cost: {out['us_per_step']:.0f} us per IMU step; final wind NED {out['final_wind_ned_ms']} m/s")
    fs = out["force_scale"]
    print(f"  force scale {fs['estimate']:.4f} +- {fs['sigma']:.4f} "
          f"(mass ratio model/true {out['model_force_ratio']:.4f})")
    ab = out["accel_bias_frd_m_s2"]
    print(f"  accelerometer bias FRD {ab['estimate']} +- {ab['sigma']} m/s^2 (zero where not estimated)")
    if out["rejected"]:
        print(f"  rejected inputs: {out['rejected']}")
    return 0
