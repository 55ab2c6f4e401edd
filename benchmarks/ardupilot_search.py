"""Source search flown by ArduCopter in windseek's world: success, path ratio, declared error, wind RMSE.

Per seed, four processes as on a real vehicle: ``windseek sitl SCENARIO --ardupilot --seed S`` (ArduPilot's
JSON physics; windseek's sensor component on ArduCopter's SERIAL2), ArduCopter SITL (``--model JSON
--speedup K``, windseek's parameter file ``sitl/ardupilot/params/windseek_nasa_quad.parm``; a fresh instance and
working directory), ``windseek estimator`` on ArduCopter's SERIAL0 (WIND_COV back through ArduPilot's routing,
scored by windseek) and ``windseek mission --strategy STRATEGY --wind estimated`` on SERIAL1 (MAVSDK: GUIDED
for the setpoints, ArduCopter's ground-station failsafe on). Rotor speeds come from windseek's ESC
telemetry component (``--esc-component 158``, ESC_TELEMETRY_1_TO_4).

Printed per seed and in all, as ``benchmarks/px4_search.py`` prints them (its ``collect`` and ``report``):
found (declared within 5 m of the true source, horizontally), declared error, path ratio, time to the
declaration, the estimator's WIND_COV RMSE against the true wind at the vehicle (airborne samples), the
lockstep speed. Evaluation seeds (1000+) by default.

Usage: ``WINDSEEK_ARDUPILOT_BIN=.../build/sitl/bin/arducopter python benchmarks/ardupilot_search.py
[--seeds 1000-1009] [--scenario open-field] [--strategy surge-cast] [--speedup 5] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from px4_search import _cli, _seeds, collect, report  # noqa: E402 - one scoring for both autopilots

from sitl.ardupilot.launch import LISTENING  # noqa: E402
from sitl.ardupilot.params import PARAMS_FILE  # noqa: E402
from sitl.ardupilot.process import ArduCopterSitl, ardupilot_binary, free_instance, ports  # noqa: E402
from sitl.autopilot_process import stop_process, wait_for_text  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402

#: EKF3's multirotor wind estimation for nasa-quad (``--autopilot-wind``; benchmarks/drag_coefficients.py).
EKF3_DRAG = {"EK3_DRAG_BCOEF_X": 115.3, "EK3_DRAG_BCOEF_Y": 115.3, "EK3_DRAG_MCOEF": 0.055}


def _home(scenario: str) -> str:
    h = load_scenario(scenario).sensors.home
    return f"{h.lat_deg:.7f},{h.lon_deg:.7f},{h.alt_m:g},0"


def trial(binary: Path, seed: int, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    """One search: the four processes, their results merged."""
    out.mkdir(parents=True, exist_ok=True)
    n = free_instance()
    p = ports(n)
    env = dict(os.environ)
    with contextlib.ExitStack() as stack:
        f = {k: stack.enter_context(open(out / k, "wb")) for k in
             ("windseek.log", "estimator.log", "estimator.json", "mission.log", "mission.json")}  # fmt: skip
        ws = subprocess.Popen(_cli("sitl", args.scenario, "--ardupilot", "--ardupilot-port", str(p["json"]),
                                   "--ardupilot-mavlink", f"127.0.0.1:{p['peripheral']}", "--seed", str(seed),
                                   "--exit-summary", str(out / "windseek.json")),
                              cwd=REPO, stdout=f["windseek.log"], stderr=subprocess.STDOUT, env=env)  # fmt: skip
        wait_for_text(out / "windseek.log", LISTENING, ws)
        params = [PARAMS_FILE]
        if args.autopilot_wind:
            params.append(out / "ekf3_drag.parm")
            params[-1].write_text("".join(f"{k} {v:g}\n" for k, v in EKF3_DRAG.items()))
        ap = ArduCopterSitl(binary, n, out / "ardupilot", out / "ardupilot.log", _home(args.scenario),
                            speedup=args.speedup, params=params).start()  # fmt: skip
        est = subprocess.Popen(_cli("estimator", "--connect", f"tcpout://127.0.0.1:{p['gcs']}", "--esc-component",
                                    "158", "--json", "--link-timeout", "60", "--connect-timeout", "120",
                                    "--vehicle", args.vehicle),
                               cwd=REPO, stdout=f["estimator.json"], stderr=f["estimator.log"], env=env)  # fmt: skip
        wall0 = time.monotonic()
        with contextlib.suppress(subprocess.TimeoutExpired):  # the mission's own limits normally end it first
            subprocess.run(_cli("mission", "--connect", f"tcpout://127.0.0.1:{p['companion']}", "--strategy",
                                args.strategy, "--wind", "estimated", "--esc-component", "158", "--seed", str(seed),
                                "--speed-hint", f"{args.speedup:g}", "--json", "--vehicle", args.vehicle),
                           cwd=REPO, stdout=f["mission.json"], stderr=f["mission.log"], env=env,
                           timeout=args.wall_limit)  # fmt: skip
        wall = time.monotonic() - wall0
        stop_process(est)
        ap.stop()  # before windseek: ArduPilot waiting for its physics ignores SIGTERM
        stop_process(ws)
    r = collect(seed, out)
    r["wall_s"] = round(wall, 1)
    return r


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1000-1009", help="A-B or a,b,c (default 1000-1009: evaluation seeds)")
    ap.add_argument("--scenario", default="open-field")
    ap.add_argument("--strategy", default="surge-cast")
    ap.add_argument("--speedup", type=float, default=5.0, help="ArduPilot's --speedup (default 5)")
    ap.add_argument("--wall-limit", type=float, default=900.0, help="wall seconds per mission")
    ap.add_argument("--keep", default=None, help="keep every run's logs under this directory")
    ap.add_argument("--vehicle", default="nasa_quad", help="the estimators' vehicle file (name or path)")
    ap.add_argument("--autopilot-wind", action="store_true", help="EKF3's multirotor wind estimation on (drag "
                    "fusion with the measured coefficients): its WIND is scored beside the estimator's")
    args = ap.parse_args()
    binary = ardupilot_binary()
    if binary is None:
        print("set WINDSEEK_ARDUPILOT_BIN to a built arducopter (build/sitl/bin/arducopter)", file=sys.stderr)
        return 2
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="ardupilot_search_"))
    print(f"{args.strategy} on {args.scenario} through ArduCopter SITL ({binary}) at --speedup {args.speedup:g}, "
          f"estimators' model {args.vehicle}; logs in {root}; load {os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
    rows = []
    for seed in _seeds(args.seeds):
        r = trial(binary, seed, args, root / f"seed{seed}")
        rows.append(r)
        print(json.dumps(r), flush=True)
    report(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
