"""The autopilot's own wind estimate beside windseek's UKF on the same flight, both against windseek's truth.

ArduCopter (``--model JSON``, windseek's parameter file) hovers at 10 m in GUIDED for ``--hover`` simulated
seconds in windseek's blade-element world, with EKF3's multirotor wind estimation configured as its
documentation says: drag fusion on with the paper's vehicle's ballistic and momentum drag coefficients
(``EK3_DRAG_BCOEF_X/Y`` 115.3 kg/m^2, ``EK3_DRAG_MCOEF`` 0.055 1/s, measured on windseek's truth by
``benchmarks/drag_coefficients.py``). On the same flight ``windseek estimator`` (the paper's UKF with the
identified model, rotor speeds from windseek's ESC telemetry) publishes WIND_COV. windseek scores both by
source (its exit summary, :mod:`sitl.hil.wind_score`): RMSE of 1-s means (N/E/D and horizontal), the mean
direction error (1-s means, winds over 1 m/s), the 95 % coverage of the stated horizontal uncertainty
(EKF3's WIND states none), and for ``paper-s1`` the time to converge after its direction step (the first
second after which the 1-s horizontal error stays under 1 m/s for 5 s). ``paper-s1``'s step comes at
23 s of the scenario, before ArduCopter has booted and taken off: here it is moved to ``--step-at`` s of
world time (a copy of the scenario file with that change).

Usage: ``WINDSEEK_ARDUPILOT_BIN=.../arducopter python benchmarks/autopilot_wind.py [--scenarios paper-s1,open-field]
[--seeds 1000-1002] [--hover 120] [--step-at 110] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
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
sys.path.insert(0, str(REPO / "benchmarks"))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from px4_search import _cli, _seeds, _stop  # noqa: E402

from sitl.ardupilot.gcs import CopterGcs  # noqa: E402
from sitl.ardupilot.params import PARAMS_FILE  # noqa: E402
from sitl.ardupilot.process import ArduCopterSitl, ardupilot_binary, free_instance, ports  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402
from wire.dialect import mavlink as M  # noqa: E402, N812

#: EKF3's multirotor drag model for nasa-quad (benchmarks/drag_coefficients.py on the blade-element truth).
EKF3_DRAG = {"EK3_DRAG_BCOEF_X": 115.3, "EK3_DRAG_BCOEF_Y": 115.3, "EK3_DRAG_MCOEF": 0.055}


def scenario_file(name: str, step_at: float, out: Path) -> str:
    """The scenario by name, or for paper-s1 a copy whose wind change comes at ``step_at`` s."""
    if name != "paper-s1":
        return name
    src = (REPO / "sitl" / "scenarios" / "paper-s1.toml").read_text()
    text = src.replace("changes = [{ t_s = 23.0,", f"changes = [{{ t_s = {step_at:g},")
    if text == src:
        raise RuntimeError("paper-s1.toml's wind change line changed: update scenario_file")
    p = out / "paper-s1-step.toml"
    p.write_text(text.replace('name = "paper-s1"', 'name = "paper-s1-step"'))
    return str(p)


def hover(g: CopterGcs, until_s: float) -> None:
    hb = g.recv("HEARTBEAT", 60.0, lambda h: h.get_srcComponent() == 1)
    if hb is None:
        raise RuntimeError("no heartbeat from ArduCopter")
    g.m.target_system = hb.get_srcSystem()
    g.request_streams(4)
    if g.arm_when_ready("GUIDED", 180.0) != 0:
        raise RuntimeError(f"ArduCopter did not arm: {g.text[-5:]}")
    if g.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0) != 0:
        raise RuntimeError(f"take-off refused: {g.text[-5:]}")
    deadline = time.monotonic() + 1200.0
    while time.monotonic() < deadline:
        m = g.recv("SYSTEM_TIME", 10.0)
        if m is not None and m.time_boot_ms / 1000.0 >= until_s:
            return
    raise RuntimeError("the hover did not reach its end time")


def trial(binary: Path, scenario: str, seed: int, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    n = free_instance()
    p = ports(n)
    drag = out / "ekf3_drag.parm"
    drag.write_text("".join(f"{k} {v:g}\n" for k, v in EKF3_DRAG.items()))
    sc = scenario_file(scenario, args.step_at, out)
    with open(out / "windseek.log", "wb") as wl, open(out / "estimator.log", "wb") as el:
        ws = subprocess.Popen(_cli("sitl", sc, "--ardupilot", "--ardupilot-port", str(p["json"]),
                                   "--ardupilot-mavlink", f"127.0.0.1:{p['peripheral']}", "--seed", str(seed),
                                   "--exit-summary", str(out / "windseek.json")),
                              cwd=REPO, stdout=wl, stderr=subprocess.STDOUT)  # fmt: skip
        deadline = time.monotonic() + 90.0
        while b"JSON physics on UDP" not in (out / "windseek.log").read_bytes() and time.monotonic() < deadline:
            time.sleep(0.1)
        h = load_scenario(sc).sensors.home
        ap = ArduCopterSitl(binary, n, out / "ardupilot", out / "ardupilot.log", f"{h.lat_deg:.7f},{h.lon_deg:.7f},"
                            f"{h.alt_m:g},0", speedup=args.speedup, params=[PARAMS_FILE, drag]).start()  # fmt: skip
        est = subprocess.Popen(_cli("estimator", "--connect", f"tcpout://127.0.0.1:{p['companion']}",
                                    "--esc-component", "158", "--json", "--link-timeout", "60", "--connect-timeout",
                                    "120"), cwd=REPO, stdout=subprocess.DEVNULL, stderr=el)  # fmt: skip
        g = CopterGcs(p["gcs"])
        try:
            hover(g, args.step_at - 30.0 + args.hover)
        finally:
            g.close()
            _stop(est)
            ap.stop()
            _stop(ws)
    s = json.loads((out / "windseek.json").read_text())
    return {"scenario": scenario, "seed": seed, "ukf": figures(s["wind_series_1s"], s["wind_coverage_95_horizontal"],
                                                              args.step_at if scenario == "paper-s1" else None),
            "ekf3": figures(s["autopilot_wind"]["series_1s"], s["autopilot_wind"]["coverage_95_horizontal"],
                            args.step_at if scenario == "paper-s1" else None)}  # fmt: skip


def figures(series: list[list[float]], coverage: float | None, step_at: float | None) -> dict[str, Any]:
    """RMSE of 1-s means (N, E, D, horizontal), direction error, coverage, time to converge after the step."""
    if not series:
        return {"seconds": 0}
    a = np.array(series)
    est, tru = a[:, 1:4], a[:, 4:7]
    e = est - tru
    rmse = np.sqrt(np.mean(e * e, axis=0))
    strong = np.hypot(tru[:, 0], tru[:, 1]) > 1.0
    d = np.degrees(np.arctan2(est[:, 1], est[:, 0]) - np.arctan2(tru[:, 1], tru[:, 0]))
    dir_err = float(np.mean(np.abs((d[strong] + 180.0) % 360.0 - 180.0))) if strong.any() else math.nan
    conv = None
    if step_at is not None:
        eh = np.hypot(e[:, 0], e[:, 1])
        after = np.flatnonzero(a[:, 0] >= step_at)
        for k in after:
            window = eh[k:k + 5]
            if len(window) == 5 and np.all(window < 1.0):
                conv = float(a[k, 0] - step_at)
                break
    return {"seconds": int(len(a)), "rmse_ned": [round(float(v), 3) for v in rmse],
            "rmse_h": round(float(math.hypot(rmse[0], rmse[1])), 3), "direction_error_deg": round(dir_err, 1),
            "coverage_95_h": coverage, "converge_after_step_s": conv}  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="paper-s1,open-field")
    ap.add_argument("--seeds", default="1000-1002")
    ap.add_argument("--hover", type=float, default=120.0, help="simulated seconds of hover scored after take-off")
    ap.add_argument("--step-at", type=float, default=110.0, help="world time of paper-s1's wind step [s]")
    ap.add_argument("--speedup", type=float, default=5.0)
    ap.add_argument("--keep", default=None)
    args = ap.parse_args()
    binary = ardupilot_binary()
    if binary is None:
        print("set WINDSEEK_ARDUPILOT_BIN to a built arducopter", file=sys.stderr)
        return 2
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="autopilot_wind_"))
    print(f"ArduCopter hover, EKF3 {EKF3_DRAG} vs windseek's UKF; logs in {root}; load {os.getloadavg()[0]:.1f}")
    rows = []
    for scenario in args.scenarios.split(","):
        for seed in _seeds(args.seeds):
            r = trial(binary, scenario, seed, args, root / f"{scenario}-{seed}")
            rows.append(r)
            print(json.dumps(r), flush=True)
    for scenario in args.scenarios.split(","):
        rs = [r for r in rows if r["scenario"] == scenario]
        for who in ("ukf", "ekf3"):
            f = [r[who] for r in rs if r[who].get("seconds")]
            if not f:
                print(f"{scenario:<12} {who:<5} no estimates scored")
                continue
            rm = np.sqrt(np.mean([np.square(x["rmse_ned"]) for x in f], axis=0))
            cov = [x["coverage_95_h"] for x in f if x["coverage_95_h"] is not None]
            conv = [x["converge_after_step_s"] for x in f if scenario == "paper-s1"]
            dirs = np.mean([x["direction_error_deg"] for x in f])
            print(f"{scenario:<12} {who:<5} RMSE 1-s N {rm[0]:.2f} E {rm[1]:.2f} D {rm[2]:.2f} horizontal "
                  f"{math.hypot(rm[0], rm[1]):.2f} m/s; direction {dirs:.1f} deg; "
                  f"coverage {np.mean(cov) if cov else float('nan'):.2f}; converge {conv}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
