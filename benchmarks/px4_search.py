"""Source search flown by PX4 in windseek's world: success, path ratio, declared error, wind RMSE.

Per seed, four processes as on a real vehicle: ``windseek sitl SCENARIO --px4 --seed S --px4-free``
(PX4's simulator, lockstep as fast as PX4 answers), PX4 SITL (airframe 10016 with windseek's
parameters, ``sitl/px4/windseek_nasa_quad.params``; a fresh instance and working directory),
``windseek estimator`` on PX4's ground-station link (WIND_COV back through PX4's forwarding) and
``windseek mission --strategy STRATEGY --wind estimated`` on PX4's API link (MAVSDK). Rotor speeds
come from windseek's ESC telemetry component (``--esc-component 158``).

The estimator's model: ``--vehicle FILE`` (given to ``windseek estimator`` and to the mission's own live
estimator; default nasa-quad's identified file), or ``--identify FILE``: first the identification flown through
PX4 (``windseek identify --connect`` on PX4's API link, offboard attitude + thrust setpoints) in windseek's
``calm`` world, paced at ``--identify-speed`` x real time (``windseek sitl calm --px4 --speed K``: the
setpoints are paced by the wall clock), rotor speeds from windseek's ESC telemetry (component 158, numbered
as its rotors: ``--esc-order rotors``), SCALED_IMU; the file written is then the ``--vehicle`` of the
searches. Both worlds fly the scenario's vehicle by its truth (nasa-quad: blade-element rotors,
``truth = "bet"``).

Printed per seed: found (declared within 5 m of the true source, horizontally), declared error,
path flown until the declaration over the start-to-source distance, time to the declaration, the
estimator's WIND_COV RMSE against the true wind at the vehicle (scored by windseek on what PX4
forwarded, airborne samples only), the lockstep speed; then the success rate, medians and the
pooled RMSE. Evaluation seeds (1000+) by default; development seeds are 100-179.

Usage: ``WINDSEEK_PX4_BIN=.../bin/px4 python benchmarks/px4_search.py [--seeds 1000-1009]
[--scenario open-field] [--strategy surge-cast] [--vehicle FILE | --identify FILE] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from sitl.autopilot_process import stop_process  # noqa: E402
from sitl.hil.px4_process import Px4Sitl, free_instance, ports, px4_binary  # noqa: E402

FOUND_M = 5.0
#: EKF2's multirotor wind estimation for nasa-quad (``--autopilot-wind``; benchmarks/drag_coefficients.py).
EKF2_DRAG = {"EKF2_DRAG_CTRL": 1, "EKF2_BCOEF_X": 115.3, "EKF2_BCOEF_Y": 115.3, "EKF2_MCOEF": 0.055}


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "windseek.cli", *args]


def _json(path: Path) -> dict[str, Any]:
    """A JSON file (an indented object), or the last line of a program's output; {} if none."""
    try:
        text = path.read_text().strip()
    except OSError:
        return {}
    for candidate in (text, text.splitlines()[-1] if text else ""):
        try:
            return dict(json.loads(candidate))
        except ValueError:
            continue
    return {}


def trial(binary: Path, seed: int, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    """One search: the four processes, their results merged."""
    out.mkdir(parents=True, exist_ok=True)
    n = free_instance()
    p = ports(n)
    env = dict(os.environ)
    with contextlib.ExitStack() as stack:
        f = {k: stack.enter_context(open(out / k, "wb")) for k in
             ("windseek.log", "estimator.log", "estimator.json", "mission.log", "mission.json")}  # fmt: skip
        ws = subprocess.Popen(_cli("sitl", args.scenario, "--px4", "--px4-port", str(p["sim"]), "--px4-free",
                                   "--seed", str(seed), "--exit-summary", str(out / "windseek.json")),
                              cwd=REPO, stdout=f["windseek.log"], stderr=subprocess.STDOUT, env=env)  # fmt: skip
        extra = {f"PX4_PARAM_{k}": f"{v:g}" for k, v in EKF2_DRAG.items()} if args.autopilot_wind else None
        px4 = Px4Sitl(binary, n, out / "px4", out / "px4.log", speed=10.0, extra_env=extra).start()
        est = subprocess.Popen(_cli("estimator", "--connect", f"udpout://127.0.0.1:{p['gcs']}", "--esc-component",
                                    "158", "--imu-average", "2", "--json", "--link-timeout", "60",
                                    "--connect-timeout", "120", "--vehicle", args.vehicle),
                               cwd=REPO, stdout=f["estimator.json"], stderr=f["estimator.log"], env=env)  # fmt: skip
        wall0 = time.monotonic()
        with contextlib.suppress(subprocess.TimeoutExpired):  # the mission's own limits normally end it first
            subprocess.run(_cli("mission", "--connect", f"udpout://127.0.0.1:{p['api']}", "--strategy", args.strategy,
                                "--wind", "estimated", "--esc-component", "158", "--seed", str(seed), "--json",
                                "--vehicle", args.vehicle),
                           cwd=REPO, stdout=f["mission.json"], stderr=f["mission.log"], env=env,
                           timeout=args.wall_limit)  # fmt: skip
        wall = time.monotonic() - wall0
        stop_process(est)
        stop_process(ws)
        px4.stop()
    r = collect(seed, out)
    r["wall_s"] = round(wall, 1)
    return r


def identify(binary: Path, path: Path, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    """The identification through PX4 in windseek's calm world (see the module docstring); its JSON summary, the
    wall time, PX4's clock speed and the world's lockstep figures. Writes the vehicle file ``path``."""
    out.mkdir(parents=True, exist_ok=True)
    n = free_instance()
    p = ports(n)
    k = str(args.identify_speed)
    with open(out / "windseek.log", "wb") as wlog:
        ws = subprocess.Popen(_cli("sitl", "calm", "--px4", "--px4-port", str(p["sim"]), "--speed", k, "--seed",
                                   str(args.identify_seed), "--exit-summary", str(out / "windseek.json")),
                              cwd=REPO, stdout=wlog, stderr=subprocess.STDOUT, env=dict(os.environ))  # fmt: skip
        try:
            with Px4Sitl(binary, n, out / "px4", out / "px4.log", speed=args.identify_speed):
                w0 = time.monotonic()
                r = subprocess.run(_cli("identify", "--connect", f"udpout://127.0.0.1:{p['api']}", "--vehicle",
                                        args.identify_base, "-o", str(path), "--esc-component", "158", "--esc-order",
                                        args.identify_esc_order, "--imu", "scaled", "--speed-hint", k, "--speed",
                                        str(args.identify_ref_speed), "--duration", str(args.identify_duration),
                                        "--validation-duration", str(args.identify_duration / 2), "--plot",
                                        str(out / "fit.png"), "--json"),
                                   cwd=REPO, capture_output=True, text=True, timeout=args.wall_limit)  # fmt: skip
                wall = time.monotonic() - w0
        finally:
            stop_process(ws)
    (out / "identify.log").write_text(r.stderr)
    (out / "identify.json").write_text(r.stdout)
    res = _json(out / "identify.json")
    res["returncode"], res["wall_s"] = r.returncode, round(wall, 1)
    res["world"] = {k: v for k, v in _json(out / "windseek.json").items()
                    if k in ("lockstep_speed", "lockstep_timeouts", "crashed")}  # fmt: skip
    return res


def identify_report(res: dict[str, Any]) -> None:
    """The identification's table: R^2 and TIC per axis, the flight's figures."""
    flight = res.get("flight") or {}
    print(f"identification through PX4: exit {res.get('returncode')}, abort {res.get('abort')}, {res.get('wall_s')} s "
          f"wall; streams {flight.get('streams', {}).get('rates_hz')}; clock {flight.get('clock_speed')}x "
          f"(max in the manoeuvres {flight.get('clock_speed_max')}x); world {res.get('world')}")  # fmt: skip
    axes = res.get("axes") or {}
    if axes:
        print("axis  R^2 %   fit TIC  val TIC")

    def num(x: Any) -> float:
        return math.nan if x is None else float(x)

    for a, m in axes.items():
        print(f"{a.upper():>4}  {num(m.get('r2_pct')):6.2f}  {num(m.get('fit_tic')):7.4f}  "
              f"{num(m.get('val_tic')):7.4f}")  # fmt: skip
    if res.get("accel_noise_m_s2"):
        print(f"accelerometer noise in the record: {res['accel_noise_m_s2']} m/s^2; max tilt "
              f"{flight.get('max_tilt_deg')} deg")  # fmt: skip


def collect(seed: int, out: Path) -> dict[str, Any]:
    """One seed's figures from the files a trial left in ``out``."""
    m, s = _json(out / "mission.json"), _json(out / "windseek.json")
    src = np.array(s.get("true_sources_ned_m") or [[math.nan] * 3])[0]
    home = np.array(m.get("home_ned") or [0.0, 0.0, 0.0])
    start_dist = float(np.hypot(*(src[:2] - home[:2])))
    err = s.get("declared_error_horizontal_m")
    if err is None and m.get("declared_ned"):
        err = float(np.hypot(*(np.array(m["declared_ned"][:2]) - src[:2])))
    return {"seed": seed, "cause": m.get("cause", "no result"), "found": err is not None and err <= FOUND_M,
            "error_m": err, "path_m": m.get("path_m"), "path_ratio": (m["path_m"] / start_dist) if m.get("path_m")
            else None, "time_s": m.get("time_s"), "rmse_ned": s.get("wind_rmse_ned_m_s"),
            "rmse_h": s.get("wind_rmse_horizontal_m_s"), "scored": s.get("wind_estimates_scored", 0),
            "rmse_ned_10s": s.get("wind_rmse_ned_after_10s_m_s"),
            "scored_10s": s.get("wind_estimates_scored_after_10s", 0),
            "lockstep_speed": s.get("lockstep_speed"), "timeouts": s.get("lockstep_timeouts"),
            "crashed": s.get("crashed"), "rmse_h_1s": s.get("wind_rmse_1s_horizontal_m_s"),
            "coverage_95_h": s.get("wind_coverage_95_horizontal"),
            "autopilot_rmse_h_1s": (s.get("autopilot_wind") or {}).get("rmse_1s_horizontal_m_s"),
            "autopilot_coverage_95_h": (s.get("autopilot_wind") or {}).get("coverage_95_horizontal")}  # fmt: skip


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(x) for x in text.split(",")]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1000-1009", help="A-B or a,b,c (default 1000-1009: evaluation seeds)")
    ap.add_argument("--scenario", default="open-field")
    ap.add_argument("--strategy", default="surge-cast")
    ap.add_argument("--wall-limit", type=float, default=900.0, help="wall seconds per mission")
    ap.add_argument("--keep", default=None, help="keep every run's logs under this directory")
    ap.add_argument("--autopilot-wind", action="store_true", help="EKF2's multirotor wind estimation on (drag "
                    "fusion with the measured coefficients): its WIND_COV is scored beside the estimator's")
    ap.add_argument("--vehicle", default="nasa_quad", help="the estimators' vehicle file (name or path; default: "
                    "nasa-quad, its model identified in-process)")  # fmt: skip
    ap.add_argument("--identify", metavar="FILE", default=None, help="first identify the vehicle through PX4 in the "
                    "calm world, write FILE and use it as --vehicle")  # fmt: skip
    ap.add_argument("--identify-base", default="nasa-quad", help="the vehicle flown in the identification (base file)")
    ap.add_argument("--identify-speed", type=float, default=4.0, help="lockstep pace of the identification, x real "
                    "time (default 4)")  # fmt: skip
    ap.add_argument("--identify-duration", type=float, default=120.0, help="fitting manoeuvre, s (the validation "
                    "manoeuvre is half of it)")  # fmt: skip
    ap.add_argument("--identify-ref-speed", type=float, default=8.0, help="peak of the horizontal velocity reference "
                    "in the identification, m/s (default 8: the searches fly at up to about 8 m/s of airspeed)")
    ap.add_argument("--identify-seed", type=int, default=1, help="world seed of the identification (calm)")
    ap.add_argument("--identify-esc-order", choices=("rotors", "px4"), default="rotors", help="how the identification "
                    "numbers windseek's ESC telemetry: rotors (right) or px4 (wrong: to see what it costs)")
    ap.add_argument("--identify-only", action="store_true", help="stop after the identification")
    ap.add_argument("--from", dest="from_dir", default=None, help="do not fly: recompute the figures from the logs "
                    "a --keep run left in this directory")  # fmt: skip
    args = ap.parse_args()
    if args.from_dir:
        rows = [collect(seed, Path(args.from_dir) / f"seed{seed}") for seed in _seeds(args.seeds)]
        for r in rows:
            print(json.dumps(r))
        report(rows)
        return 0
    binary = px4_binary()
    if binary is None:
        print("set WINDSEEK_PX4_BIN to a PX4 SITL binary (build/px4_sitl_*/bin/px4)", file=sys.stderr)
        return 2
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="px4_search_"))
    if args.identify:
        print(f"identifying {args.identify_base} through PX4 in the calm world at {args.identify_speed:g}x; load "
              f"{os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
        path = Path(args.identify).resolve()
        res = identify(binary, path, args, root / "identify")
        identify_report(res)
        if res["returncode"] != 0 or not path.exists():
            print(f"the identification failed (exit {res['returncode']}): see {root / 'identify'}", file=sys.stderr)
            return 1
        args.vehicle = str(path)
        if args.identify_only:
            return 0
    rows = []
    print(f"{args.strategy} on {args.scenario} through PX4 SITL ({binary}), estimators' model {args.vehicle}; "
          f"logs in {root}; load "
          f"{os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
    for seed in _seeds(args.seeds):
        r = trial(binary, seed, args, root / f"seed{seed}")
        rows.append(r)
        print(json.dumps(r), flush=True)
    report(rows)
    return 0


def _pooled(rows: list[dict[str, Any]], key: str) -> tuple[int, np.ndarray]:
    """(estimates, RMSE N/E/D) over every seed's scored estimates (the per-seed RMSEs weighted by count)."""
    ok = [r for r in rows if r.get(f"scored{key}") and r.get(f"rmse_ned{key}") and r[f"rmse_ned{key}"][0] is not None]
    n = sum(r[f"scored{key}"] for r in ok)
    if not n:
        return 0, np.full(3, math.nan)
    return n, np.sqrt(sum(r[f"scored{key}"] * np.square(r[f"rmse_ned{key}"]) for r in ok) / n)


def report(rows: list[dict[str, Any]]) -> None:
    """The success rate, medians and the pooled wind RMSE of the seeds' rows."""
    found = [r for r in rows if r["found"]]
    ratios = [r["path_ratio"] for r in found if r["path_ratio"]]
    errs = [r["error_m"] for r in found]
    print(f"success {len(found)}/{len(rows)} ({100 * len(found) / len(rows):.0f} %) within {FOUND_M:g} m")
    if found:
        print(f"path / start distance (found): median {np.median(ratios):.2f} (min {min(ratios):.2f}, "
              f"max {max(ratios):.2f}); declared error: median {np.median(errs):.2f} m (max {max(errs):.2f} m); "
              f"time to declaration: median {np.median([r['time_s'] for r in found]):.1f} s")  # fmt: skip
    for key, what in (("", "airborne"), ("_10s", "airborne, 10 s after each lift-off on")):
        n_sc, pooled = _pooled(rows, key)
        if n_sc:
            print(f"WIND_COV RMSE vs truth (pooled over {n_sc} {what} estimates): N {pooled[0]:.3f} "
                  f"E {pooled[1]:.3f} D {pooled[2]:.3f} m/s, horizontal {math.hypot(pooled[0], pooled[1]):.3f} m/s")
    for key, who in (("rmse_h_1s", "windseek's estimator"), ("autopilot_rmse_h_1s", "the autopilot's own estimate")):
        v = [r[key] for r in rows if r.get(key) is not None]
        if v:
            cov = [r[k] for r in rows if (k := key.replace("rmse_h_1s", "coverage_95_h")) and r.get(k) is not None]
            print(f"{who}: horizontal RMSE of 1-s means median {np.median(v):.2f} m/s ({min(v):.2f}-{max(v):.2f}, "
                  f"{len(v)} flights); 95 % coverage median {np.median(cov) if cov else math.nan:.2f}")  # fmt: skip
    print(f"lockstep speed: median {np.median([r['lockstep_speed'] or 0 for r in rows]):.2f}x; lockstep timeouts: "
          f"{sum(r['timeouts'] or 0 for r in rows)}; crashes: {sum(bool(r['crashed']) for r in rows)}; load "
          f"{os.getloadavg()[0]:.1f}")  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(main())
