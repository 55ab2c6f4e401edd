"""Trial recordings' sizes: in-process trials recorded as a batch trial is, and where each file's bytes go.

Flies trials (``run_trial(..., recorder=TrialRecorder(path))``; open-field unless ``--scenario``) for each
strategy and seed and prints each file's size split as :mod:`benchmarks.rrd_bytes` splits it (recording
temporal / static, blueprint, footer). ``--legacy`` records each trial a second time the way trials were
recorded before 2026-12-06 (the posterior as raw RGBA, the footer written, every scalar series an entity
of its own: ``TrialRecorder(png_images=False, footer=True, shared_rows=False)``) and prints the ratio.
Run on an older checkout (without ``--legacy``) for its figures.

    python benchmarks/recording_size.py                                   # surge-cast and infotaxis, 3 seeds
    python benchmarks/recording_size.py --strategies surge-cast --seeds 1000,1001 --legacy
    python benchmarks/recording_size.py --scenario paper-s4 --strategies surge-cast --seeds 101
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from toolchain import numba_cache  # noqa: E402

numba_cache.configure()

from benchmarks.rrd_bytes import breakdown  # noqa: E402
from mission.runners.inprocess import run_trial  # noqa: E402
from recording.trial import TrialRecorder  # noqa: E402


def parts(path: Path) -> dict[str, int]:
    """A file's bytes: total, recording temporal / static, blueprint, footer, chunks."""
    size, chunks, other = breakdown(path)
    out: Counter[str] = Counter({"total": size, "chunks": len(chunks)})
    for c in chunks:
        out["blueprint" if c.store == "blueprint" else f"{'static' if c.static else 'temporal'}"] += c.bytes
    out["footer"] = sum(v for k, v in other.items() if k.startswith("footer"))
    return dict(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="open-field")
    ap.add_argument("--strategies", default="surge-cast,infotaxis")
    ap.add_argument("--seeds", default="1000,1001,1002")
    ap.add_argument("--time-limit", type=float, default=150.0, metavar="S")
    ap.add_argument("--legacy", action="store_true", help="also record each trial the pre-2026-12-06 way")
    a = ap.parse_args()
    ratios: list[float] = []
    with tempfile.TemporaryDirectory() as d:
        for strategy in a.strategies.split(","):
            for seed in (int(s) for s in a.seeds.split(",")):
                path = Path(d) / f"{strategy}-{seed}.rrd"
                r = run_trial(a.scenario, strategy, seed=seed, time_limit_s=a.time_limit,
                              recorder=TrialRecorder(path))  # fmt: skip
                p = parts(path)
                line = (f"{strategy:11s} seed {seed}: {r.time_s if r.success else a.time_limit:5.1f} s, "
                        f"{p['total']:9,d} B ({p['chunks']} chunks: temporal {p.get('temporal', 0):,}, static "
                        f"{p.get('static', 0):,}, blueprint {p.get('blueprint', 0):,}, footer {p['footer']:,})")
                if a.legacy:
                    old = Path(d) / f"{strategy}-{seed}-legacy.rrd"
                    former = TrialRecorder(old, png_images=False, footer=True, shared_rows=False)
                    run_trial(a.scenario, strategy, seed=seed, time_limit_s=a.time_limit, recorder=former)
                    q = parts(old)
                    ratios.append(p["total"] / q["total"])
                    line += f"; legacy {q['total']:9,d} B (footer {q['footer']:,}): x{ratios[-1]:.3f}"
                print(line, flush=True)
    if ratios:
        print(f"new / legacy: x{min(ratios):.3f} .. x{max(ratios):.3f} over {len(ratios)} trials")


if __name__ == "__main__":
    main()
