"""``windseek sim SCENARIO``: run a scenario headless in lockstep and print a summary."""

from __future__ import annotations

import argparse
import json
import math
import time

from sitl.scenario import load_scenario
from sitl.simulation import Simulation


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sim",
        help="run a scenario headless in lockstep and print a summary",
        description="Run a scenario (built-in name such as paper-s1, or a .toml path) as fast as "
        "possible in lockstep and print its figures of merit.",
    )
    p.add_argument("scenario", help="built-in scenario name or path to a scenario .toml")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds (default: the scenario's)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def simulate(scenario_name: str, duration: float | None, seed: int | None, progress: bool = False) -> dict:
    """Run a scenario and return the summary dictionary (see README, ``windseek sim``)."""
    sc = load_scenario(scenario_name)
    if duration is not None:
        sc = sc.with_duration(duration)
    sim = Simulation(sc, seed=seed)
    chunk = 1.0
    n_chunks = max(1, math.ceil(sc.duration_s / chunk))
    t0 = time.perf_counter()
    if progress:
        from rich.progress import Progress

        with Progress(transient=True) as bar:
            task = bar.add_task(f"sim {sc.name}", total=sc.duration_s)
            for _ in range(n_chunks):
                sim.run_until(min(sc.duration_s, sim.t + chunk))
                bar.update(task, completed=sim.t)
    else:
        sim.run_until(sc.duration_s)
    wall = time.perf_counter() - t0
    out = {
        "scenario": sc.name,
        "seed": sim.seed,
        "sim_time_s": round(sim.t, 6),
        "wall_time_s": round(wall, 4),
        "realtime_factor": round(sim.t / wall, 2) if wall > 0 else math.inf,
        "position_error_rms_m": round(sim.stats.position_error_rms_m, 4),
        "max_tilt_deg": round(math.degrees(sim.stats.max_tilt_rad), 3),
        "crashed": sim.crashed,
        "final_position_ned_m": [round(float(v), 3) for v in sim.position],
        "mode": sim.fc.mode.value,
        "armed": sim.fc.armed,
        "mission_item": sim.fc.mission_index,
        "mission_items": len(sim.fc.mission),
    }
    for key, value in sim.summary_extras().items():
        out[key] = value
    return out


def run(args: argparse.Namespace) -> int:
    out = simulate(args.scenario, args.duration, args.seed, progress=not (args.json or args.no_progress))
    if args.json:
        print(json.dumps(out))
    else:
        print(f"scenario {out['scenario']} (seed {out['seed']})")
        print(
            f"  simulated {out['sim_time_s']:.1f} s in {out['wall_time_s']:.2f} s wall: "
            f"{out['realtime_factor']:.0f}x real time"
        )
        print(f"  position error RMS vs commanded path: {out['position_error_rms_m']:.3f} m")
        print(f"  max tilt: {out['max_tilt_deg']:.1f} deg   crashed: {out['crashed']}")
        print(f"  final position NED: {out['final_position_ned_m']} m, mode {out['mode']}, "
              f"mission item {out['mission_item']}/{out['mission_items']}")
        for key in out:
            if key.startswith(("plume_", "chem_")):
                print(f"  {key}: {out[key]}")
    return 1 if out["crashed"] else 0
