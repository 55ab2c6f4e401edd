"""The command-line options the search benchmarks share: trials, the first seed, processes.

Seeds 100-179 are the development set (what the strategies were tuned on); seeds 200-299 a
second one (infotaxis's refit of 2026-12-03, after the first had been tuned on too often); the
evaluation set starts at 1000 (``search_table.py``) and is never used while tuning.
"""

from __future__ import annotations

import argparse

#: First seed of the development set.
DEV_SEED = 100


def parser(doc: str, trials: int) -> argparse.ArgumentParser:
    """An argument parser described by the first line of ``doc``, with ``--trials`` (default
    ``trials``), ``--seed`` (default the development set's first seed) and ``--jobs``."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--trials", type=int, default=trials)
    ap.add_argument("--seed", type=int, default=DEV_SEED, help="first seed (trial i uses seed + i)")
    ap.add_argument("--jobs", type=int, default=2, help="processes")
    return ap
