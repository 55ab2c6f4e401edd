"""Infotaxis detection model against the simulator's puff plume: P(a hit in a 0.5 s bin).

Stationary sensors (the simulator's first-order sensor model: tau 0.5 s, noise 0.01, detection
limit 0.05 mg/m^3, 10 Hz) on a grid of downwind x / crosswind y / height z about the source of a
scenario, for ``--seeds`` development seeds x 145 s of the puff plume. A reading is a *hit* as
the strategies count one (``PlumeMemory.add``: above the limit and above the pure decay of the
last detected reading by ``HIT_SIGMAS`` sigmas of the difference of two readings), a bin of 5
readings is a hit if any is. The figure: the observed bin-hit
probability next to the strategy's model (``mission.strategies.ste_model``, the meander random
effect marginalized over its nodes, the intermittent-plume chain at its stationary share) with the
parameters fitted here by least squares -- intermittency length, meander fraction, meander
direction sigma, source radius and the effective release rate -- and with the strategy's defaults.

    python benchmarks/infotaxis_detection_model.py [--scenario open-field] [--seeds 8] [--no-fit]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from mission.strategies import params_from_table
from mission.strategies.params import InfotaxisParams
from mission.strategies.plume_memory import hit_threshold
from mission.strategies.ste_model import detection_prob_node, meander_nodes, model_constants
from sitl.scenario import load_scenario
from sitl.simulation import Simulation

XS = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0, 30.0, 45.0, 60.0, 90.0)
YS = (0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0)
ZS = (2.0, 3.0, 5.0)
#: The strategy's model before the refit (L, meander fraction, meander deg, source radius), for comparison.
PREVIOUS_DEFAULTS = (40.0, 0.5, 7.0, 0.3)


def _defaults() -> InfotaxisParams:
    p = params_from_table("infotaxis", None)
    assert isinstance(p, InfotaxisParams)
    return p


def observe(scenario: str, seeds: int) -> tuple[np.ndarray, np.ndarray]:
    """Grid points (x downwind, y crosswind, z height) [m] and their bin-hit probability."""
    pts = np.array([[x, y, z] for x in XS for y in YS for z in ZS])
    sc = load_scenario(scenario)
    tau, lim, noise, dt = 0.5, 0.05, 0.01, 0.1
    a = math.exp(-dt / tau)
    hits = np.zeros(len(pts))
    n_bins = 0
    for seed in range(100, 100 + seeds):
        sim = Simulation(sc, seed=seed, autostart_route=False)
        plume = sim.plume
        if plume is None:
            raise SystemExit(f"scenario {scenario!r} has no [plume] table")
        src = np.asarray(plume.config.sources[0].position_ned)
        w = sim.wind.mean(0.0, src)
        down = np.array([w[0], w[1]]) / math.hypot(w[0], w[1])
        cross = np.array([-down[1], down[0]])
        world = np.column_stack([src[0] + pts[:, 0] * down[0] + pts[:, 1] * cross[0],
                                 src[1] + pts[:, 0] * down[1] + pts[:, 1] * cross[1], -pts[:, 2]])
        rng = np.random.default_rng(seed)
        state = np.zeros(len(pts))
        tail_v = np.zeros(len(pts))  # the last detected reading and its time, per point
        tail_t = np.full(len(pts), -np.inf)
        in_bin = np.zeros(len(pts), bool)
        t = plume.t
        for k in range(1500):
            plume.step(t, dt)
            t += dt
            state += (1.0 - a) * (plume.concentration(world) - state)
            r = np.maximum(state + noise * rng.standard_normal(len(pts)), 0.0)
            det = r >= lim
            k_tail = np.exp(-(t - tail_t) / tau)
            in_bin |= det & (r > hit_threshold(tail_v, k_tail, noise))
            tail_v = np.where(det, r, tail_v)
            tail_t = np.where(det, t, tail_t)
            if k % 5 == 4:
                if k > 50:
                    hits += in_bin
                    n_bins += 1
                in_bin[:] = False
    return pts, hits / n_bins


def model(pts: np.ndarray, length: float, fraction: float, meander_deg: float, radius: float, q: float, u: float,
          stability: str) -> np.ndarray:
    """The strategy's P(hit in a bin) at the grid points (source at 2 m, ``radius`` m)."""
    p = _defaults()
    mc = model_constants(stability, radius, length, p.detection_limit_mg_m3, p.false_alarm,
                         p.upwind_reach_m, fraction, math.radians(meander_deg))
    nodes, logw = meander_nodes(int(p.meander_nodes))
    wts = np.exp(logw)
    pairs = list(zip(nodes, wts, strict=True))
    return np.array([sum(wj * detection_prob_node(x, y, z, 2.0, q, u, xj, mc) for xj, wj in pairs) for x, y, z in pts])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="open-field")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--no-fit", action="store_true")
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    u = float(np.hypot(*sc.wind.velocity_ned[0:2]))
    if sc.plume is None:
        raise SystemExit(f"scenario {args.scenario!r} has no [plume] table")
    stability = sc.plume.plume.stability
    pts, obs = observe(args.scenario, args.seeds)
    p = _defaults()
    def with_rate(shape: tuple[float, float, float, float]) -> tuple[float, float, float, float, float]:
        """The release rate is a free dimension of the posterior: fit it alone for a fixed shape."""
        lq = minimize_scalar(lambda lq: float(np.sum((model(pts, *shape, 10.0**lq, u, stability) - obs) ** 2)),
                             bounds=(-3.0, 3.0), method="bounded").x
        return (*shape, float(10.0**lq))

    fits = {"defaults (rate fitted)": with_rate((p.intermittency_length_m, p.meander_fraction, p.meander_deg,
                                                 p.source_radius_m)),
            "defaults before 2026-12-03 (rate fitted)": with_rate(PREVIOUS_DEFAULTS)}
    if not args.no_fit:
        def loss(th: np.ndarray) -> float:
            length, frac, deg, radius, lq = th
            if not (1.0 < length < 500.0 and 0.0 <= frac < 0.99 and 0.0 <= deg < 45.0 and 0.01 <= radius < 10.0):
                return 1e9
            return float(np.sum((model(pts, length, frac, deg, radius, 10.0**lq, u, stability) - obs) ** 2))

        best = minimize(loss, np.array([30.0, 0.5, 7.0, 0.3, 0.5]), method="Nelder-Mead",
                        options={"maxiter": 600, "xatol": 1e-3, "fatol": 1e-6})
        length, frac, deg, radius, lq = best.x
        fits["fitted"] = (length, frac, deg, radius, 10.0**lq)
    for name, (length, frac, deg, radius, q) in fits.items():
        mod = model(pts, length, frac, deg, radius, q, u, stability)
        rms = [float(np.sqrt(np.mean((mod - obs)[pts[:, 2] == z] ** 2))) for z in ZS]
        print(f"{name}: intermittency length {length:.1f} m, meander fraction {frac:.2f}, meander {deg:.1f} deg, "
              f"source radius {radius:.2f} m, effective rate {q:.2f} g/s; loss {np.sum((mod - obs) ** 2):.3f}; "
              "rms error at z = 2 / 3 / 5 m: " + " / ".join(f"{r:.3f}" for r in rms))
    print(f"\n{args.scenario}, {args.seeds} seeds, P(hit in a 0.5 s bin) at 2 m height (source height), "
          "observed / model (last fit)")
    print("| x downwind m | " + " | ".join(f"y {y:g}" for y in YS) + " |")
    print("|---:|" + "---:|" * len(YS))
    for x in XS:
        sel = (pts[:, 0] == x) & (pts[:, 2] == 2.0)
        print(f"| {x:g} | " + " | ".join(f"{o:.2f} / {m:.2f}" for o, m in zip(obs[sel], mod[sel], strict=True)) + " |")


if __name__ == "__main__":
    main()
