"""The UKF wind estimator's accuracy along search flights (issue 20): near buildings and in the open.

    python benchmarks/urban_wind_accuracy.py [--scenario paper-s4] [--strategy zigzag] [--params FILE]
        [--seeds 10] [--seed0 1000] [--near 10] [--far 25]

Each seed flies one search mission of the in-process runner (``mission.runners.inprocess.run_trial``,
estimated wind: the estimator the strategy flies on); a probe samples at every strategy tick
(10 Hz) the estimate and its 1-sigma, the true wind at the vehicle (instantaneous, and the mean of
the simulator's truth rows since the previous tick, so that the trailing 1-s mean of the truth is
the exact mean over the 250 Hz rows), the true *mean* field at the vehicle (no turbulence) and the
position. Figures are those of ``benchmarks/wind_accuracy.py`` (``estimator.metrics.accuracy``:
RMSE per axis N/E/D against the instantaneous truth and of the 1-s means, 1- and 2-sigma coverage
against the instantaneous truth, direction of the 1-s means), taken over the airborne instants
from 5 s after lift-off, and split by the vehicle's distance to the nearest building (3-D, to the
box: footprint distance horizontally, height above the roof vertically): "near" <= ``--near`` m,
"open" > ``--far`` m, "between" in the middle. Flights are pooled by sample count (RMSE = root of
the sample-weighted mean square). Diagnostics per band: rms rate of change of the true mean wind
along the track (what a random-walk wind state must follow), rms turbulence (instantaneous minus
the mean field), the mean true speed and the rms vertical component of the true mean wind (the
default ``uncalibrated`` preset models the vertical wind as mean-reverting to zero, 3 s).

Evaluation seeds start at 1000 (the search tables'); development seeds are 100-139.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from estimator.metrics import Accuracy, accuracy, moving_average  # noqa: E402
from mission.runners.inprocess import run_trial  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402
from sitl.simulation import T_WIND, Simulation  # noqa: E402

STRATEGY_FILES = Path(__file__).resolve().parent.parent / "mission" / "strategy_files"
#: Airborne: above this height over home [m]; figures from ``WARMUP_S`` after the first such tick.
AIRBORNE_M = 1.0
WARMUP_S = 5.0


class _TruthBlock:
    """Wraps the runner's wind source: before each update, the mean true wind over the truth rows
    of the tick (the estimated source consumes and clears them)."""

    def __init__(self, inner: Any, sim: Simulation) -> None:
        self.inner, self.sim, self.mode = inner, sim, inner.mode
        self.block = np.zeros(3)

    def update(self, drained: dict[str, list]) -> Any:
        rows = self.sim.truth_log
        if rows:
            self.block = np.concatenate(rows)[:, T_WIND].mean(axis=0)
        else:
            self.block = np.asarray(self.sim.wind_at_vehicle, dtype=float)
        return self.inner.update(drained)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


class WindProbe:
    """A ``run_trial`` recorder that samples the estimate and the truth at every strategy tick."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []

    def attach(self, sim: Simulation, vehicle: Any, strategy: Any, params: Any) -> None:
        self.sim, self.vehicle = sim, vehicle
        self.truth = _TruthBlock(vehicle.wind_source, sim)
        vehicle.wind_source = self.truth
        vehicle.tick_hooks.append(self.tick)

    def tick(self, t: float) -> None:
        info, sim = self.vehicle.wind_info, self.sim
        if info is None or info.cov_ned is None:
            return
        pos = np.asarray(sim.position, dtype=float)
        sig = np.sqrt(np.maximum(np.diag(info.cov_ned), 0.0))
        mean = np.asarray(sim.wind.mean(sim.t, pos), dtype=float)
        self.rows.append(np.concatenate([[t], info.wind_ned, sig, sim.wind_at_vehicle, self.truth.block, mean, pos]))

    def finish(self, result: Any) -> None:
        pass

    def arrays(self) -> dict[str, np.ndarray]:
        """t (K,), est/sigma/true/true_block/mean/pos (K, 3)."""
        a = np.array(self.rows)
        names = ("est", "sigma", "true", "true_block", "mean", "pos")
        return {"t": a[:, 0], **{n: a[:, 1 + 3 * i : 4 + 3 * i] for i, n in enumerate(names)}}


def building_distance(pos: np.ndarray, scenario: Any) -> np.ndarray:
    """3-D distance [m] of each NED position (K, 3) to the nearest building box (inf without any)."""
    d = np.full(len(pos), np.inf)
    if scenario.urban is None:
        return d
    pts = shapely.points(pos[:, 0], pos[:, 1])
    alt = -pos[:, 2]
    for b in scenario.urban.buildings:
        dh = shapely.distance(shapely.Polygon(np.asarray(b.footprint(), dtype=float)), pts)
        d = np.minimum(d, np.hypot(dh, np.maximum(0.0, alt - float(b.height_m))))
    return d


def fly(scenario: str, strategy: str, seed: int, params_path: str | None) -> tuple[dict[str, np.ndarray], Any]:
    probe = WindProbe()
    res = run_trial(scenario, strategy, "estimated", seed=seed, params_path=params_path, recorder=probe)
    return probe.arrays(), res


def bands(a: dict[str, np.ndarray], dist: np.ndarray, near_m: float, far_m: float) -> dict[str, np.ndarray]:
    """Masks of the evaluated instants: all, near, between, open."""
    air = -a["pos"][:, 2] > AIRBORNE_M
    t_air = a["t"][air][0] if np.any(air) else math.inf
    ok = air & (a["t"] >= t_air + WARMUP_S)
    return {"all": ok, "near": ok & (dist <= near_m), "between": ok & (dist > near_m) & (dist <= far_m),
            "open": ok & (dist > far_m)}  # fmt: skip


def band_figures(a: dict[str, np.ndarray], m: np.ndarray) -> tuple[Accuracy, np.ndarray]:
    """The accuracy over mask ``m``, and the diagnostics' sums (n, sum |dU/dt|^2, sum |u'|^2, sum |U|, sum W^2)
    (U the true mean wind, W its vertical component, u' the turbulence)."""
    if not m.any():
        nan3 = (math.nan,) * 3
        acc = Accuracy(nan3, nan3, math.nan, math.nan, math.nan, math.nan, math.nan, nan3, None, math.nan, 0)
    else:
        acc = accuracy(a["t"], a["est"], a["sigma"], a["true"], warmup_s=-math.inf, select=m,
                       true_avg=moving_average(a["t"], a["true_block"], 1.0))  # fmt: skip
    dudt = np.gradient(a["mean"], a["t"], axis=0)
    turb = a["true"] - a["mean"]
    U = a["mean"][m]
    diag = np.array([m.sum(), np.sum(dudt[m] ** 2), np.sum(turb[m] ** 2), np.sum(np.linalg.norm(U, axis=1)),
                     np.sum(U[:, 2] ** 2)])  # fmt: skip
    return acc, diag


def pool(accs: list[Accuracy]) -> dict[str, Any]:
    """Sample-weighted pooling of per-flight figures (RMSEs as root mean squares)."""
    n = np.array([a.samples for a in accs], dtype=float)
    if n.sum() == 0:
        return {"samples": 0}
    w = n / n.sum()
    ms = lambda xs: np.sqrt(np.sum(w[:, None] * np.array(xs, dtype=float) ** 2, axis=0))  # noqa: E731
    mean = lambda xs: float(np.sum(w * np.nan_to_num(np.array(xs, dtype=float))))  # noqa: E731
    return {"samples": int(n.sum()), "rmse": ms([a.rmse_ms for a in accs]),
            "rmse_avg": ms([a.rmse_avg_ms for a in accs]),
            "dir": float(np.sqrt(mean([a.direction_rmse_deg**2 for a in accs]))),
            "cov1": mean([a.coverage_1sigma for a in accs]), "cov2": mean([a.coverage_2sigma for a in accs]),
            "cov2_axis": np.sum(w[:, None] * np.array([a.coverage_2sigma_axis for a in accs]), axis=0)}  # fmt: skip


def row(name: str, p: dict[str, Any], d: np.ndarray) -> str:
    if p["samples"] == 0:
        return f"| {name} | 0 | - | - | - | - | - | - | - | - | - | - |"
    f3 = lambda v: " / ".join(f"{x:.2f}" for x in v)  # noqa: E731
    h = math.hypot(p["rmse_avg"][0], p["rmse_avg"][1])
    n = d[0]
    return (
        f"| {name} | {p['samples'] / 10:.0f} s | {f3(p['rmse'])} | {f3(p['rmse_avg'])} | {h:.2f} | {p['dir']:.1f} "
        f"| {p['cov1']:.3f} | {p['cov2']:.3f} ({f3(p['cov2_axis'])}) | {math.sqrt(d[1] / n):.2f} "
        f"| {math.sqrt(d[2] / n):.2f} | {d[3] / n:.1f} | {math.sqrt(d[4] / n):.2f} |"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--scenario", default="paper-s4")
    ap.add_argument("--strategy", default="zigzag")
    ap.add_argument("--params", default="", help="strategy file of mission/strategy_files (by name)")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--near", type=float, default=10.0, help="near a building: within this distance [m]")
    ap.add_argument("--far", type=float, default=25.0, help="in the open: farther than this [m]")
    args = ap.parse_args(argv)
    sc = load_scenario(args.scenario)
    params_path = str(STRATEGY_FILES / f"{args.params}.toml") if args.params else None
    per: dict[str, list[Accuracy]] = {k: [] for k in ("all", "near", "between", "open")}
    diag = {k: np.zeros(5) for k in per}
    last = args.seed0 + args.seeds - 1
    print(f"{args.scenario} / {args.strategy} {args.params} / estimated, seeds {args.seed0}..{last}")
    for seed in range(args.seed0, args.seed0 + args.seeds):
        c0 = time.process_time()
        a, res = fly(args.scenario, args.strategy, seed, params_path)
        dist = building_distance(a["pos"], sc)
        for k, m in bands(a, dist, args.near, args.far).items():
            acc, d = band_figures(a, m)
            per[k].append(acc)
            diag[k] += d
        al = per["all"][-1]
        print(f"  seed {seed}: {res.cause or 'success'}, {al.samples / 10:.0f} s airborne,"
              f" near {per['near'][-1].samples / 10:.0f} s,"
              f" 1-s RMSE N/E/D {np.round(al.rmse_avg_ms, 2)}, 2-sigma {al.coverage_2sigma:.3f}"
              f" ({time.process_time() - c0:.0f} s CPU)", flush=True)  # fmt: skip
    print(
        "| band | time | RMSE total N/E/D | RMSE 1-s N/E/D | horiz 1-s | dir 1-s (deg) | 1-sigma coverage "
        "| 2-sigma coverage (N/E/D) | rms d(mean wind)/dt (m/s^2) | rms turbulence (m/s) | mean speed (m/s) "
        "| rms mean vertical (m/s) |"
    )
    print("|---|---:|---|---|---:|---:|---:|---|---:|---:|---:|---:|")
    labels = {"all": "all", "near": f"near (<= {args.near:g} m)", "between": f"{args.near:g}-{args.far:g} m",
              "open": f"open (> {args.far:g} m)"}  # fmt: skip
    for k in per:
        print(row(labels[k], pool(per[k]), diag[k]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
