"""``python -m mission.runners.record_trial SCENARIO STRATEGY``: fly one in-process trial and record it.

The runner flies (:func:`mission.runners.inprocess.run_trial`); the recording listens
(:class:`recording.trial.TrialRecorder` attaches to the trial's simulation and vehicle). Open the
``.rrd`` with ``rerun FILE.rrd``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mission.runners.inprocess import run_trial
from recording.trial import WIND_SOURCES, TrialRecorder


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mission.runners.record_trial",
                                 description="Fly one in-process trial and record it to a .rrd "
                                 "(open it with: rerun FILE.rrd)")  # fmt: skip
    ap.add_argument("scenario")
    ap.add_argument("strategy")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--wind", default="estimated", choices=sorted(WIND_SOURCES))
    ap.add_argument("--time-limit", type=float, default=None, metavar="S")
    ap.add_argument("-o", "--out", default=None, help="output .rrd (default logs/trial-<scenario>-<strategy>.rrd)")
    a = ap.parse_args(argv)
    out = Path(a.out or f"logs/trial-{Path(a.scenario).stem}-{a.strategy}.rrd")
    r = run_trial(a.scenario, a.strategy, wind=a.wind, seed=a.seed, time_limit_s=a.time_limit,
                  recorder=TrialRecorder(out))  # fmt: skip
    print(f"{r.scenario} / {r.strategy} / seed {r.seed}: {'found' if r.success else 'not found'} "
          f"({r.cause or 'declared'}), error {r.error_m:.1f} m, {r.wall_s:.1f} s wall; wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
