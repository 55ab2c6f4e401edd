"""Batch evaluation: N seeded trials of one strategy / wind mode / scenario, in parallel processes.

Trial ``i`` uses seed ``seed + i`` (the simulation's seed: wind, turbulence, plume, sensors,
and the strategy's seeded choices), so a batch is reproducible whatever ``jobs`` is.
Statistics (:func:`summarize`):
- success rate: declared within the strategy's success radius of the true source, horizontally
  (5 m; 3 m for infotaxis: ``TrialResult.success_radius_m``), and within 3 m and 5 m for every
  strategy (``within_3m_rate``, ``within_5m_rate``);
- median and 90th-percentile time to declaration (s from t = 0 on the ground, successful trials);
- the two path measures of issue 19 over the start distance, medians over the successful trials:
  the declare ratio (``path_ratio_median``: take-off to the declaration) and the reach ratio
  (``reach_ratio_median``: until the vehicle first came within 2 m of the source, horizontally;
  a trial that never did counts as infinite);
- for strategies that state a credible region: the share of declarations whose region contains
  the true source (``credible_coverage``) and the mean stated confidence (``confidence_mean``);
- failures by cause (``declared-far``, ``timeout``, ``geofence``, ``crash``, ``takeoff``).
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
from collections import Counter
from dataclasses import dataclass

import numpy as np

from mission.runners.inprocess import TrialResult, run_trial


@dataclass(frozen=True)
class TrialSpec:
    """One trial to run (picklable)."""

    scenario: str
    strategy: str
    wind: str
    seed: int
    params_path: str | None = None
    time_limit_s: float | None = None
    model: str | None = None


def _run(spec: TrialSpec) -> TrialResult:
    return run_trial(spec.scenario, spec.strategy, spec.wind, seed=spec.seed, params_path=spec.params_path,
                     time_limit_s=spec.time_limit_s, model=spec.model)


def run_batch(
    scenario: str,
    strategy: str,
    wind: str,
    trials: int,
    seed: int | None = None,
    jobs: int = 1,
    params_path: str | None = None,
    time_limit_s: float | None = None,
    progress: bool = True,
    label: str | None = None,
    model: str | None = None,
) -> list[TrialResult]:
    """Run ``trials`` seeded trials (``jobs`` processes) and return the results in seed order."""
    from sitl.scenario import load_scenario

    if trials < 1:
        raise ValueError(f"trials = {trials}: must be >= 1")
    if jobs < 1:
        raise ValueError(f"jobs = {jobs}: must be >= 1")
    # Validate names and parameters in this process, so a mistake is one clear error, not N.
    sc = load_scenario(scenario)
    if sc.plume is None:
        raise ValueError(f"scenario {sc.name!r} has no [plume] table: nothing to search for")
    from mission.strategies import load_params
    from mission.wind_modes import INPROCESS_WIND_MODES

    load_params(strategy, params_path)
    if wind not in INPROCESS_WIND_MODES:
        raise ValueError(f"wind mode {wind!r}: choose one of {', '.join(INPROCESS_WIND_MODES)}")
    seed0 = sc.seed if seed is None else int(seed)
    if model is not None:
        from vehicle.vehicle_file import load_vehicle

        load_vehicle(model)  # a bad file is one clear error here, not N in the workers
    specs = [TrialSpec(scenario, strategy, wind, seed0 + i, params_path, time_limit_s, model) for i in range(trials)]
    results: list[TrialResult] = []
    label = label or f"{strategy}/{wind} on {sc.name}"
    ctx = mp.get_context("fork" if os.name == "posix" else "spawn")

    def consume(it) -> None:
        if not progress:
            results.extend(it)
            return
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        cols = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
        with Progress(*cols, transient=True) as bar:
            task = bar.add_task(label, total=len(specs))
            for r in it:
                results.append(r)
                bar.advance(task)

    if jobs == 1 or trials == 1:
        consume(map(_run, specs))
    else:
        with ctx.Pool(min(jobs, trials)) as pool:
            consume(pool.imap_unordered(_run, specs))
    results.sort(key=lambda r: r.seed)
    return results


def _reach(r: TrialResult) -> float:
    """Reach ratio, infinite for a trial that never came within the reach radius."""
    return math.inf if math.isnan(r.reach_ratio) else r.reach_ratio


def summarize(results: list[TrialResult]) -> dict:
    """Summary statistics of a batch (see module docstring); NaN where there is no success."""
    n = len(results)
    ok = [r for r in results if r.success]
    times = np.array([r.time_s for r in ok])
    ratios = np.array([r.path_ratio for r in ok])
    causes = Counter(r.cause for r in results if not r.success)
    cred = [r for r in results if r.credible_contains is not None]
    first = results[0] if results else None
    return {
        "scenario": first.scenario if first else "",
        "strategy": first.strategy if first else "",
        "wind": first.wind if first else "",
        "world_truth": first.world_truth if first else "",
        "estimator_model": first.estimator_model if first else "",
        "trials": n,
        "successes": len(ok),
        "success_rate": len(ok) / n if n else math.nan,
        "time_median_s": float(np.median(times)) if len(ok) else math.nan,
        "time_p90_s": float(np.percentile(times, 90)) if len(ok) else math.nan,
        "path_ratio_median": float(np.median(ratios)) if len(ok) else math.nan,
        "reach_ratio_median": float(np.median([_reach(r) for r in ok])) if ok else math.nan,
        "never_reached": sum(math.isnan(r.reach_ratio) for r in ok),
        "within_3m_rate": sum(r.error_m <= 3.0 for r in results) / n if n else math.nan,
        "within_5m_rate": sum(r.error_m <= 5.0 for r in results) / n if n else math.nan,
        "credible_coverage": float(np.mean([bool(r.credible_contains) for r in cred])) if cred else math.nan,
        "credible_radius_median_m": float(np.median([r.credible_radius_m for r in cred])) if cred else math.nan,
        "confidence_mean": float(np.mean([r.confidence for r in cred])) if cred else math.nan,
        "error_median_m": float(np.median([r.error_m for r in ok])) if ok else math.nan,
        "failures": dict(sorted(causes.items())),
        "seeds_failed": [r.seed for r in results if not r.success],
        "wall_s_mean": float(np.mean([r.wall_s for r in results])) if n else math.nan,
    }
