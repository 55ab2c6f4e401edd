"""The autopilots' own wind estimates beside windseek's UKF on the same flight, all against windseek's truth.

**PX4** (``--autopilot px4``): PX4 SITL (airframe 10016, windseek's parameters) with windseek as its simulator
over HIL (lockstep as fast as PX4 answers) hovers at 10 m after an arm + take-off through pymavlink, with EKF2's
multirotor wind estimation on as its documentation says: ``EKF2_DRAG_CTRL 1``, ``EKF2_BCOEF_X/Y`` 115.3 kg/m^2,
``EKF2_MCOEF`` 0.055 1/s (the same measured coefficients); EKF2's WIND_COV reaches windseek on PX4's payload
link (component 1: scored as the autopilot's), ``windseek estimator`` runs on PX4's ground-station link.

**ArduPilot** (``--autopilot ardupilot``): ArduCopter (``--model JSON``, windseek's parameter file) hovers
at 10 m in GUIDED for ``--hover`` simulated
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

A scenario with a route (``paper-s2``: 30 m upwind and 30 m across at 3 m/s, with holds) is flown after the
take-off to 10 m as a mission (the route's waypoints relative to the take-off point, the scenario's cruise
speed, each waypoint's hold; uploaded with the MAVLink mission protocol): by ArduCopter in AUTO, by PX4 in
AUTO.MISSION (started with MAV_CMD_MISSION_START), and scored over the same time; printed with it: the path
flown (windseek's truth, take-off included) and the distance of the end point from the last waypoint.

Usage: ``WINDSEEK_ARDUPILOT_BIN=.../arducopter WINDSEEK_PX4_BIN=.../px4 python benchmarks/autopilot_wind.py
[--autopilot ardupilot|px4] [--scenarios paper-s1,open-field] [--seeds 1000-1002] [--hover 120] [--step-at 110]
[--keep DIR] [--rrd]`` (``--rrd``: each flight's Rerun recording beside its logs).
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
from px4_search import _cli, _seeds  # noqa: E402

from sitl.ardupilot.gcs import CopterGcs  # noqa: E402
from sitl.ardupilot.launch import LISTENING  # noqa: E402
from sitl.ardupilot.params import PARAMS_FILE  # noqa: E402
from sitl.ardupilot.process import ArduCopterSitl, ardupilot_binary, free_instance, ports  # noqa: E402
from sitl.autopilot_process import stop_process, wait_for_text  # noqa: E402
from sitl.scenario import load_scenario  # noqa: E402
from wire.dialect import mavlink as M  # noqa: E402, N812

#: EKF3's and EKF2's multirotor drag model for nasa-quad (benchmarks/drag_coefficients.py on the blade-element truth).
EKF3_DRAG = {"EK3_DRAG_BCOEF_X": 115.3, "EK3_DRAG_BCOEF_Y": 115.3, "EK3_DRAG_MCOEF": 0.055}
EKF2_DRAG = {"EKF2_DRAG_CTRL": 1, "EKF2_BCOEF_X": 115.3, "EKF2_BCOEF_Y": 115.3, "EKF2_MCOEF": 0.055}
#: PX4's AUTO.MISSION, its heartbeat's custom_mode >> 16: main mode AUTO 4, sub mode MISSION 4 (px4_custom_mode.h).
PX4_AUTO_MISSION = 4 | 4 << 8


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


def route_items(sc_path: str) -> list[tuple[float, ...]]:
    """The scenario's route as ArduCopter mission items (speed, then each waypoint with its hold), [] for a hover."""
    sc = load_scenario(sc_path)
    wps = sc.route.waypoints
    if len(wps) < 2:
        return []
    h = sc.sensors.home
    dn = 1.0 / 111320.0
    de = dn / math.cos(math.radians(h.lat_deg))
    items: list[tuple[float, ...]] = [(M.MAV_CMD_DO_CHANGE_SPEED, 0.0, 0.0, 0.0, 1.0, sc.route.cruise_speed_m_s)]
    for w in wps:
        n, e, d = w.position_ned
        items.append((M.MAV_CMD_NAV_WAYPOINT, h.lat_deg + n * dn, h.lon_deg + e * de, -d, w.hold_s))
    return items


def hover(g: CopterGcs, until_s: float, route: list[tuple[float, ...]] | None = None) -> None:
    """Arm in GUIDED, take off to 10 m, with a ``route`` fly it in AUTO; until ArduCopter's clock reads ``until_s``."""
    g.guided_takeoff(10.0)
    if route:
        if g.recv("GLOBAL_POSITION_INT", 120.0, lambda p: p.relative_alt > 9000) is None:
            raise RuntimeError("did not reach 9 m")
        if g.upload_mission(route) != M.MAV_MISSION_ACCEPTED or g.set_mode("AUTO") != 0:
            raise RuntimeError(f"the route was not accepted: {g.text[-5:]}")
    deadline = time.monotonic() + 1200.0
    while time.monotonic() < deadline:
        m = g.recv("SYSTEM_TIME", 10.0)
        if m is not None and m.time_boot_ms / 1000.0 >= until_s:
            return
    raise RuntimeError("the hover did not reach its end time")


def _rrd(args: argparse.Namespace, out: Path) -> list[str]:
    """``--rrd``: windseek's Rerun recording of the flight (truth, the UKF, the autopilot's own estimate)."""
    return ["--rrd", str(out / "windseek.rrd")] if args.rrd else []


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
                                   "--exit-summary", str(out / "windseek.json"), *_rrd(args, out)),
                              cwd=REPO, stdout=wl, stderr=subprocess.STDOUT)  # fmt: skip
        wait_for_text(out / "windseek.log", LISTENING, ws)
        h = load_scenario(sc).sensors.home
        ap = ArduCopterSitl(binary, n, out / "ardupilot", out / "ardupilot.log", f"{h.lat_deg:.7f},{h.lon_deg:.7f},"
                            f"{h.alt_m:g},0", speedup=args.speedup, params=[PARAMS_FILE, drag]).start()  # fmt: skip
        est = subprocess.Popen(_cli("estimator", "--connect", f"tcpout://127.0.0.1:{p['companion']}",
                                    "--esc-component", "158", "--json", "--link-timeout", "60", "--connect-timeout",
                                    "120", *_est_args(args, out)),
                               cwd=REPO, stdout=subprocess.DEVNULL, stderr=el)  # fmt: skip
        g = CopterGcs(p["gcs"])
        try:
            hover(g, args.step_at - 30.0 + args.hover, route_items(sc))
        finally:
            g.close()
            stop_process(est)
            ap.stop()
            stop_process(ws)
    return _rows(scenario, seed, json.loads((out / "windseek.json").read_text()), args, "ekf3")


def trial_px4(binary: Path, scenario: str, seed: int, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    from px4_lockstep import _Telemetry

    from sitl.hil.px4_process import Px4Sitl
    from sitl.hil.px4_process import free_instance as px4_instance
    from sitl.hil.px4_process import ports as px4_ports

    out.mkdir(parents=True, exist_ok=True)
    n = px4_instance()
    p = px4_ports(n)
    sc = scenario_file(scenario, args.step_at, out)
    env = {f"PX4_PARAM_{k}": f"{v:g}" for k, v in EKF2_DRAG.items()}
    with open(out / "windseek.log", "wb") as wl, open(out / "estimator.log", "wb") as el:
        ws = subprocess.Popen(_cli("sitl", sc, "--px4", "--px4-port", str(p["sim"]), "--px4-free", "--seed", str(seed),
                                   "--exit-summary", str(out / "windseek.json"), *_rrd(args, out)),
                              cwd=REPO, stdout=wl, stderr=subprocess.STDOUT)  # fmt: skip
        px4 = Px4Sitl(binary, n, out / "px4", out / "px4.log", speed=10.0, extra_env=env).start()
        est = subprocess.Popen(_cli("estimator", "--connect", f"udpout://127.0.0.1:{p['gcs']}", "--esc-component",
                                    "158", "--imu-average", "2", "--json", "--link-timeout", "60",
                                    "--connect-timeout", "120", *_est_args(args, out)),
                               cwd=REPO, stdout=subprocess.DEVNULL, stderr=el)  # fmt: skip
        tel = _Telemetry(p["api"])
        route = route_items(sc)
        try:
            end, sent = time.monotonic() + 1200.0, -1e9
            while tel.t_px4 < args.step_at - 30.0 + args.hover:
                if time.monotonic() > end:
                    raise RuntimeError("the hover did not reach its end time")
                if tel.alt < 0.5 and time.monotonic() - sent > 10.0 and tel.t_px4 > 10.0:
                    home = tel.home_amsl if tel.home_amsl is not None else load_scenario(sc).sensors.home.alt_m
                    tel.command(400, 1, 0, 0, 0, 0, 0, 0)  # arm
                    tel.command(22, 0, 0, 0, math.nan, math.nan, math.nan, home + 10.0)  # take off to 10 m
                    sent = time.monotonic()
                if route and tel.alt > 9.0:
                    fly_route_px4(tel, route)
                    route = []
                time.sleep(0.2)
        finally:
            log = {"reached": tel.reached, "text": tel.text, "acks": tel.acks}
            (out / "px4_mission.json").write_text(json.dumps(log))
            tel.close()
            stop_process(est)
            stop_process(ws)
            px4.stop()
    return _rows(scenario, seed, json.loads((out / "windseek.json").read_text()), args, "ekf2")


def _est_args(args: argparse.Namespace, out: Path) -> list[str]:
    """The estimator's input telemetry log (for ``benchmarks/compass_replay.py``) and its compass setting."""
    return ["--tlog", str(out / "estimator.tlog"), "--compass" if args.compass else "--no-compass",
            "--px4-scaled-imu-hz", str(args.px4_scaled_imu_hz)]


def fly_route_px4(tel: Any, route: list[tuple[float, ...]], timeout_s: float = 60.0) -> None:
    """Upload ``route`` (:func:`route_items`) as PX4's mission and start it (MAV_CMD_MISSION_START from item 0:
    PX4's commander switches to AUTO.MISSION); RuntimeError with PX4's last words if it refuses.

    Started is when PX4 acknowledges the command or its heartbeat shows AUTO.MISSION; a refusal (the commander
    sees the new mission's validity a moment after the upload's ACK) is retried, a missing answer is not: a
    second MISSION_START would send PX4 back to item 0 of a mission it is already flying."""
    if tel.upload_mission(route) != M.MAV_MISSION_ACCEPTED:
        raise RuntimeError(f"PX4 did not accept the route: {tel.text[-5:]}")
    deadline, send = time.monotonic() + timeout_s, True
    while time.monotonic() < deadline:
        if send:
            tel.clear()
            tel.command(M.MAV_CMD_MISSION_START, 0, 0)
            send = False
        ack = tel.wait("COMMAND_ACK", 0.5, lambda a: a.command == M.MAV_CMD_MISSION_START)
        if (tel.custom_mode >> 16) & 0xFFFF == PX4_AUTO_MISSION or (ack and ack.result == M.MAV_RESULT_ACCEPTED):
            return
        if ack is not None:  # refused: again in a moment
            time.sleep(0.5)
            send = True
    raise RuntimeError(f"PX4 did not start the mission: {tel.text[-5:]}, acks {tel.acks[-5:]}")


def _route(sc_path: str, s: dict[str, Any]) -> dict[str, Any] | None:
    """The path flown (windseek's truth) and the end point's distance from the route's last waypoint, m."""
    wps = load_scenario(sc_path).route.waypoints
    if len(wps) < 2:
        return None
    d = np.array(s["final_position_ned_m"]) - np.array(wps[-1].position_ned)
    return {"path_m": s["path_length_m"], "end_from_last_waypoint_m": round(float(np.linalg.norm(d)), 2),
            "end_from_last_waypoint_horizontal_m": round(float(np.hypot(d[0], d[1])), 2)}  # fmt: skip


def _rows(scenario: str, seed: int, s: dict[str, Any], args: argparse.Namespace, who: str) -> dict[str, Any]:
    step = args.step_at if scenario == "paper-s1" else None
    return {"scenario": scenario, "seed": seed, "route": _route(scenario, s),
            "ukf": figures(s["wind_series_1s"], s["wind_coverage_95_horizontal"], step),
            who: figures(s["autopilot_wind"]["series_1s"], s["autopilot_wind"]["coverage_95_horizontal"], step)}


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
    ap.add_argument("--autopilot", choices=("ardupilot", "px4"), default="ardupilot")
    ap.add_argument("--compass", action=argparse.BooleanOptionalAction, default=True,
                    help="the estimator's compass check of the autopilot's heading (estimator/compass.py)")
    ap.add_argument("--px4-scaled-imu-hz", type=float, default=100.0,
                    help="the estimator's rate for PX4's SCALED_IMU (its IMU input on PX4)")
    ap.add_argument("--rrd", action="store_true", help="also write each flight's Rerun recording (windseek.rrd in "
                    "its --keep directory): the truth, windseek's UKF and the autopilot's own estimate")
    args = ap.parse_args()
    if args.autopilot == "px4":
        from sitl.hil.px4_process import px4_binary

        binary, run, who, what = px4_binary(), trial_px4, "ekf2", f"PX4 hover/route, EKF2 {EKF2_DRAG}"
    else:
        binary, run, who, what = ardupilot_binary(), trial, "ekf3", f"ArduCopter hover/route, EKF3 {EKF3_DRAG}"
    if binary is None:
        print("set WINDSEEK_ARDUPILOT_BIN / WINDSEEK_PX4_BIN to the autopilot's SITL build", file=sys.stderr)
        return 2
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="autopilot_wind_"))
    print(f"{what} vs windseek's UKF; logs in {root}; load {os.getloadavg()[0]:.1f}")
    rows = []
    for scenario in args.scenarios.split(","):
        for seed in _seeds(args.seeds):
            r = run(binary, scenario, seed, args, root / f"{scenario}-{seed}")
            rows.append(r)
            print(json.dumps(r), flush=True)
    for scenario in args.scenarios.split(","):
        rs = [r for r in rows if r["scenario"] == scenario]
        for name in ("ukf", who):
            f = [r[name] for r in rs if r[name].get("seconds")]
            if not f:
                print(f"{scenario:<12} {name:<5} no estimates scored")
                continue
            rm = np.sqrt(np.mean([np.square(x["rmse_ned"]) for x in f], axis=0))
            cov = [x["coverage_95_h"] for x in f if x["coverage_95_h"] is not None]
            conv = [x["converge_after_step_s"] for x in f if scenario == "paper-s1"]
            dirs = np.mean([x["direction_error_deg"] for x in f])
            print(f"{scenario:<12} {name:<5} RMSE 1-s N {rm[0]:.2f} E {rm[1]:.2f} D {rm[2]:.2f} horizontal "
                  f"{math.hypot(rm[0], rm[1]):.2f} m/s; direction {dirs:.1f} deg; "
                  f"coverage {np.mean(cov) if cov else float('nan'):.2f}; converge {conv}")  # fmt: skip
        flown = [r["route"] for r in rs if r["route"]]
        if flown:
            paths, ends = [f["path_m"] for f in flown], [f["end_from_last_waypoint_m"] for f in flown]
            print(f"{scenario:<12} route: path flown {min(paths):.1f}-{max(paths):.1f} m, ending "
                  f"{min(ends):.2f}-{max(ends):.2f} m from the last waypoint")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
