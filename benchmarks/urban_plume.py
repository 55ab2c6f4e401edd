"""The plume among buildings: what a puff's wind costs, and what a 5 Hz plume update would change.

1. A puff's wind sample (mean field, turbulence multiplier, turbulence: ``wind_velocity_many``) at
   the puffs of a paper-s4 plume after 60 s, CPU per puff, against the same call at the puffs of
   an open-field plume (the peer: the same kernel in open terrain), in the same run.
2. paper-s4 with its plume updated at 5 Hz instead of 10 (a copy of the scenario with only
   ``update_rate_hz`` changed): the plume's mean concentration and the fraction of 0.1 s samples
   above the sensor's 0.05 mg/m^3 detection limit at 2 m height, 20 / 50 / 90 m downwind of the
   source along the line to the start, over 120 s after the warm-up, per seed; the same seeds for
   both rates. (The simulator's speed of the copy: ``sim_speed.py --scenario COPY --reference
   paper-s4``.) Usage:

    python benchmarks/urban_plume.py [--seeds 11-22]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from toolchain import numba_cache  # before any kernel module

numba_cache.configure()
from sitl.scenario import load_scenario  # noqa: E402
from sitl.simulation import Simulation  # noqa: E402
from sitl.world.wind.kernel import wind_velocity_many  # noqa: E402

SCENARIOS = Path(__file__).resolve().parents[1] / "sitl" / "scenarios"
DETECTION_MG_M3 = 0.05
DOWNWIND_M = (20.0, 50.0, 90.0)


def puff_sample_us(scenario: str, repeats: int = 300) -> float:
    """CPU us per puff of one ``wind_velocity_many`` call at a 60 s plume's puffs (best of 3)."""
    sim = Simulation(load_scenario(scenario).with_duration(62.0), seed=1)
    sim.run(60.0)
    pts = np.ascontiguousarray(sim.world.plume.puff_array()[:, :3])
    kernel = sim.world.wind._kernel
    wind_velocity_many(1.0, pts, kernel)
    best = float("inf")
    for _ in range(3):
        c0 = time.process_time()
        for i in range(repeats):
            wind_velocity_many(1.0 + 0.1 * i, pts, kernel)
        best = min(best, (time.process_time() - c0) / repeats / len(pts) * 1e6)
    return best


def plume_statistics(path: str | Path, seeds: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(mean concentration, detection fraction), each (seeds, points), at the points downwind."""
    src, start = np.array([428.4, 118.4]), np.array([340.0, 30.0])  # paper-s4's source and start
    d = (start - src) / np.linalg.norm(start - src)
    pts = np.array([[*(src + r * d), -2.0] for r in DOWNWIND_M])
    means, hits = [], []
    for seed in seeds:
        sim = Simulation(load_scenario(path).with_duration(200.0), seed=seed)
        c = []
        for _ in range(1200):
            sim.run(0.1)
            c.append(np.asarray(sim.plume.concentration(pts)))
        arr = np.array(c)
        means.append(arr.mean(axis=0))
        hits.append((arr > DETECTION_MG_M3).mean(axis=0))
    return np.array(means), np.array(hits)


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b or a) + 1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=_seeds, default=_seeds("11-22"), help="seed range of the plume comparison")
    args = ap.parse_args()
    urban, open_ = puff_sample_us("paper-s4"), puff_sample_us("open-field")
    print(f"puff wind sample: paper-s4 {urban:.3f} us, open-field {open_:.3f} us per puff "
          f"(paper-s4 / open-field = {urban / open_:.1f})")  # fmt: skip
    text = (SCENARIOS / "paper-s4.toml").read_text()
    assert "update_rate_hz = 10.0" in text
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "paper-s4-5hz.toml"
        copy.write_text(text.replace("update_rate_hz = 10.0", "update_rate_hz = 5.0"))
        n = len(args.seeds)
        print(f"plume at 2 m, {', '.join(f'{r:g}' for r in DOWNWIND_M)} m downwind, seeds {args.seeds[0]}-"
              f"{args.seeds[-1]}: mean mg/m^3 (standard error) | detection fraction (standard error)")  # fmt: skip
        for label, path in (("10 Hz", "paper-s4"), ("5 Hz", copy)):
            m, h = plume_statistics(path, args.seeds)
            se = np.sqrt(n) if n > 1 else 1.0
            cols = " ".join(f"{a:.2f} ({b:.2f})" for a, b in zip(m.mean(0), m.std(0, ddof=min(1, n - 1)) / se,
                                                                 strict=True))  # fmt: skip
            hcols = " ".join(f"{a:.3f} ({b:.3f})" for a, b in zip(h.mean(0), h.std(0, ddof=min(1, n - 1)) / se,
                                                                  strict=True))  # fmt: skip
            print(f"  {label:6s} {cols} | {hcols}", flush=True)


if __name__ == "__main__":
    main()
