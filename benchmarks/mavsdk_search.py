"""Source search through the MAVSDK runner against windseek's SITL, seed by seed, beside the in-process runner.

Per seed one ``windseek demo --scenario SC --strategy ST [--params FILE] --seed S --speed K --json``: the
SITL, the wind estimator (its WIND_COV is the mission's wind) and the MAVSDK mission as three processes
over local UDP, paced by the wall clock (K x real time), in a city with the scenario's buildings given
to the mission (``--buildings``). The demo's summary is split into ``mission.json`` and ``windseek.json``
in the seed's folder and scored by ``benchmarks/px4_search.py``'s ``collect`` (one scoring for every
autopilot path); the strategy's own success radius (3 m for infotaxis, ``SUCCESS_RADIUS_BY_STRATEGY``)
decides "found", as in the in-process tables.

Printed per seed: found, declared error (horizontal), stated confidence, whether the 90 % credible
region (the strategy's radius about its declaration) held the source, time to the declaration (vehicle
s from arming), path / start distance, setpoints re-planned around buildings (the mission's clamped
setpoints), the estimator's WIND_COV RMSE N/E/D against the truth (airborne), how long the vehicle
hovered in ``solve-field`` (the urban field's solve, vehicle s from the tlog's STATUSTEXT) and the
wall time with the load average at the seed's start; then the totals. With ``--inprocess`` the same
seeds by ``windseek search SC --strategy ST --params FILE --trials N --seed S0 --jobs 1 --json``
(or ``--inprocess-json FILE``, a saved output of that command) side by side.

Usage::

    python benchmarks/mavsdk_search.py --seeds 1000-1009 --scenario paper-s4 --strategy infotaxis \\
        --params mission/strategy_files/urban.toml --speed 3 --keep DIR --inprocess
    python benchmarks/mavsdk_search.py --from DIR --seeds 1000-1009 ...   # recompute from the logs a run kept
    python benchmarks/mavsdk_search.py --from DIR --seeds 1001 --replay-estimator   # the estimator's verdict offline
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
from px4_search import _cli, _json, _pooled, _seeds, collect  # noqa: E402 - one scoring for every runner

from mission.runners.inprocess import SUCCESS_RADIUS_BY_STRATEGY, SUCCESS_RADIUS_M  # noqa: E402


def fly(seed: int, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    """One seed through ``windseek demo``: its summary split into the files ``collect`` reads, and the row."""
    out.mkdir(parents=True, exist_ok=True)
    argv = ["demo", "--scenario", args.scenario, "--strategy", args.strategy, "--seed", str(seed), "--speed",
            f"{args.speed:g}", "--logs", str(out), "--wall-limit", f"{args.wall_limit:g}", "--json",
            *(["--params", args.params] if args.params else []), *(["--no-rrd"] if args.no_rrd else [])]  # fmt: skip
    load = calm(args.max_load, args.load_wait)
    wall0 = time.monotonic()
    drops = {"estimator": 0, "mission": 0}
    with open(out / "demo.log", "w") as log, open(out / "demo.json", "w") as stdout:
        demo = subprocess.Popen(_cli(*argv), cwd=REPO, stdout=stdout, stderr=log)
        end = wall0 + args.wall_limit + 180.0  # the demo's own --wall-limit normally ends it first
        while demo.poll() is None and time.monotonic() < end:
            time.sleep(1.0)
            for who, n in udp_drops(out).items():
                drops[who] = max(drops[who], n)
        if demo.poll() is None:
            demo.kill()
        rc = demo.wait(10.0)
    summary = _json(out / "demo.json")
    (out / "mission.json").write_text(json.dumps(summary.get("mission") or {}))
    (out / "windseek.json").write_text(json.dumps(summary.get("truth") or {}))
    meta = {"returncode": rc, "load": round(load, 2), "wall_s": round(time.monotonic() - wall0, 1), "udp_drops": drops}
    (out / "run.json").write_text(json.dumps(meta))
    return row(seed, args.strategy, out)


#: The line of each process's log that names its UDP port (127.0.0.1:PORT).
PORT_LINES = {"estimator": "windseek estimator: connecting on udpin://127.0.0.1:",
              "mission": "mission: connected to system 1 on udpin://127.0.0.1:"}  # fmt: skip


def udp_drops(out: Path) -> dict[str, int]:
    """Datagrams the kernel dropped so far at the estimator's and the mission's sockets (their receive buffers
    full: the process did not read fast enough), from ``/proc/net/udp`` (Linux; {} elsewhere)."""
    ports = {}
    for who, prefix in PORT_LINES.items():
        for log in out.glob(f"*.{who}.log"):
            with open(log, errors="replace") as f:
                ports.update({int(ln[len(prefix):].split()[0]): who for ln in f if ln.startswith(prefix)})
    try:
        rows = Path("/proc/net/udp").read_text().splitlines()[1:]
    except OSError:
        return {}
    got: dict[str, int] = {}
    for ln in rows:
        col = ln.split()
        port = int(col[1].split(":")[1], 16)
        if port in ports:
            got[ports[port]] = got.get(ports[port], 0) + int(col[-1])
    return got


def calm(max_load: float | None, wait_s: float) -> float:
    """The 1-min load average, after waiting (at most ``wait_s``) for it to fall below ``max_load``: the processes
    pace by the wall clock, and a loaded machine delays their ticks."""
    end = time.monotonic() + wait_s
    while max_load is not None and os.getloadavg()[0] > max_load and time.monotonic() < end:
        time.sleep(10.0)
    return os.getloadavg()[0]


def row(seed: int, strategy: str, out: Path) -> dict[str, Any]:
    """One seed's figures from its folder: ``collect``'s, found within the strategy's success radius, the
    credible region, the re-planned setpoints, the ``solve-field`` hover and the run's wall time and load."""
    r = collect(seed, out)
    m, run = _json(out / "mission.json"), _json(out / "run.json")
    radius = SUCCESS_RADIUS_BY_STRATEGY.get(strategy, SUCCESS_RADIUS_M)
    err, cred = r["error_m"], m.get("credible_radius_m")
    declared = m.get("cause") == "declared" and err is not None
    r.update(found=bool(declared and err <= radius), radius_m=radius,
             confidence=m.get("confidence") if declared else None, credible_radius_m=cred,
             held=None if not declared or cred is None else bool(err <= cred), replanned=m.get("clamped_setpoints"),
             returncode=run.get("returncode"), load=run.get("load"), wall_s=run.get("wall_s"),
             udp_drops=run.get("udp_drops"),
             states=states(out))  # fmt: skip
    hover = [s for s in r["states"] if s["state"] == "solve-field"]
    r["solve_field_s"] = round(sum(s["vehicle_s"] for s in hover), 2) if hover else None
    r["solve_field_wall_s"] = round(sum(s["wall_s"] for s in hover), 2) if hover else None
    return r


def states(out: Path) -> list[dict[str, Any]]:
    """The strategy states the mission published (STATUSTEXT ``state: NAME`` in the SITL's tlog), each with
    how long it lasted in vehicle seconds (the SITL's LOCAL_POSITION_NED clock) and wall seconds (the tlog's
    stamps)."""
    tlogs = sorted(out.glob("*.tlog"))
    if not tlogs:
        return []
    from pymavlink import mavutil

    from wire.dialect import mavlink as mav

    mavutil.mavlink = mav
    conn = mavutil.mavlink_connection(str(tlogs[-1]))
    t_veh, marks = math.nan, []
    while (msg := conn.recv_match(type=["LOCAL_POSITION_NED", "STATUSTEXT"])) is not None:
        if msg.get_type() == "LOCAL_POSITION_NED":
            t_veh = msg.time_boot_ms * 1e-3
        elif msg.get_srcComponent() == 190 and str(msg.text).startswith("state: "):
            marks.append((str(msg.text)[len("state: "):].strip(), t_veh, float(getattr(msg, "_timestamp", math.nan))))
    conn.close()
    marks.append(("end", t_veh, marks[-1][2] if marks else math.nan))
    return [{"state": a[0], "t_s": round(a[1], 2), "vehicle_s": round(b[1] - a[1], 2), "wall_s": round(b[2] - a[2], 2)}
            for a, b in zip(marks, marks[1:], strict=False)]  # fmt: skip


def replay_estimator(out: Path, imu_average: int = 2) -> dict[str, Any]:
    """The demo's estimator (``windseek estimator --imu-average N``, its ``LiveCore``) fed offline every frame
    the SITL's tlog holds, in order: whether its model-fit verdict (a latched "model mismatch" withholds the
    wind; the mission then aborts with ``estimator-fault``) follows from the flight itself or from the live run
    (datagrams dropped, a late process)."""
    from pymavlink import mavutil

    from windseek import cmd_estimator
    from wire.dialect import mavlink as mav

    tlogs = sorted(out.glob("*.tlog"))
    if not tlogs:
        return {}
    ap = argparse.ArgumentParser()
    cmd_estimator.add_parser(ap.add_subparsers())
    core = cmd_estimator.make_core(ap.parse_args(["estimator", "--connect", "udpin://127.0.0.1:1", "--imu-average",
                                                  str(imu_average)]))  # fmt: skip
    mavutil.mavlink = mav
    conn = mavutil.mavlink_connection(str(tlogs[-1]))
    while (msg := conn.recv_match()) is not None:
        if (msg.get_srcSystem(), msg.get_srcComponent()) != (1, 191):  # not the estimator's own WIND_COV
            core.handle(msg)
            core.take_notes()
    conn.close()
    s = core.summary()
    return {k: s.get(k) for k in ("model_fits", "mismatch_t_s", "innovation_nis_mean", "model_note")}


def _f(v: Any, fmt: str = ".1f") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def print_rows(rows: list[dict[str, Any]]) -> None:
    """The per-seed table (markdown)."""
    print("| seed | found | cause | declared error m | confidence | 90 % region (m) held | time to declaration s | "
          "path ratio | re-planned setpoints | wind RMSE N / E / D m/s | solve-field hover s (wall) | wall s | load | "
          "UDP drops estimator / mission |")
    print("|---|---|---|---:|---:|---|---:|---:|---:|---|---|---:|---:|---|")
    for r in rows:
        rm = r.get("rmse_ned") or [None] * 3
        dr = r.get("udp_drops") or {}
        held = "-" if r["held"] is None else f"{'yes' if r['held'] else 'no'} ({_f(r['credible_radius_m'])})"
        print(f"| {r['seed']} | {'yes' if r['found'] else 'no'} | {r['cause']} | {_f(r['error_m'], '.2f')} | "
              f"{_f(r['confidence'], '.2f')} | {held} | {_f(r['time_s'])} | {_f(r['path_ratio'], '.2f')} | "
              f"{_f(r['replanned'], 'd')} | {' / '.join(_f(x, '.2f') for x in rm)} | "
              f"{_f(r['solve_field_s'])} ({_f(r['solve_field_wall_s'])}) | {_f(r['wall_s'], '.0f')} | "
              f"{_f(r['load'], '.1f')} | {_f(dr.get('estimator'), 'd')} / {_f(dr.get('mission'), 'd')} |")  # fmt: skip


def totals(rows: list[dict[str, Any]]) -> None:
    """Found, declarations, the region's calibration, medians, the pooled wind RMSE, failures."""
    n = len(rows)
    found = [r for r in rows if r["found"]]
    decl = [r for r in rows if r["cause"] == "declared"]
    held = [r for r in decl if r["held"]]
    radius = rows[0]["radius_m"] if rows else SUCCESS_RADIUS_M
    print(f"found (within {radius:g} m) {len(found)} / {n}; declared {len(decl)}, the 90 % region held the source in "
          f"{len(held)} / {len(decl)}; mean stated confidence "
          f"{_f(float(np.mean([r['confidence'] for r in decl])) if decl else None, '.2f')}")  # fmt: skip
    if found:
        print(f"successes: time to declaration median {np.median([r['time_s'] for r in found]):.0f} s, path ratio "
              f"median {np.median([r['path_ratio'] for r in found]):.2f}, declared error median "
              f"{np.median([r['error_m'] for r in found]):.2f} m")  # fmt: skip
    fails = [f"{r['seed']}: {r['cause']}" + (f" {r['error_m']:.1f} m" if r["error_m"] is not None else "")
             for r in rows if not r["found"]]  # fmt: skip
    print(f"not found: {', '.join(fails) or 'none'}; demo exit status {sorted({str(r['returncode']) for r in rows})}; "
          f"crashes {sum(bool(r['crashed']) for r in rows)}")  # fmt: skip
    n_sc, pooled = _pooled(rows, "")
    if n_sc:
        print(f"WIND_COV RMSE vs truth (pooled over {n_sc} airborne estimates): N {pooled[0]:.3f} E {pooled[1]:.3f} "
              f"D {pooled[2]:.3f} m/s, horizontal {math.hypot(pooled[0], pooled[1]):.3f} m/s")  # fmt: skip
    drops = [r["udp_drops"] for r in rows if r.get("udp_drops") is not None]
    if drops:
        print(f"UDP datagrams the kernel dropped at the estimator's socket: {sum(d['estimator'] for d in drops)} in "
              f"{sum(d['estimator'] > 0 for d in drops)} of {len(drops)} flights; at the mission's: "
              f"{sum(d['mission'] for d in drops)}")  # fmt: skip
    hover = [r["solve_field_s"] for r in rows if r["solve_field_s"] is not None]
    if hover:
        print(f"solve-field hover: {len(hover)} flights, {min(hover):.1f}-{max(hover):.1f} vehicle s (median "
              f"{np.median(hover):.1f})")  # fmt: skip
    walls = [r["wall_s"] for r in rows if r["wall_s"] is not None]
    loads = [r["load"] for r in rows if r["load"] is not None]
    if walls:
        print(f"wall {sum(walls):.0f} s in all ({np.mean(walls):.0f} s a seed); load average at the seeds' starts "
              f"{min(loads):.1f}-{max(loads):.1f}")  # fmt: skip


def inprocess(args: argparse.Namespace, seeds: list[int], out: Path) -> dict[int, dict[str, Any]]:
    """The in-process runner's trials on the same seeds (consecutive from the first), by seed."""
    if args.inprocess_json:
        data = json.loads(Path(args.inprocess_json).read_text())
    else:
        if seeds != list(range(seeds[0], seeds[0] + len(seeds))):
            raise SystemExit("--inprocess: the seeds must be consecutive (windseek search --seed S --trials N)")
        argv = ["search", args.scenario, "--strategy", args.strategy, "--trials", str(len(seeds)), "--seed",
                str(seeds[0]), "--jobs", "1", "--json", *(["--params", args.params] if args.params else [])]
        r = subprocess.run(_cli(*argv), cwd=REPO, capture_output=True, text=True, timeout=120.0 * len(seeds) + 300)
        (out / "inprocess.json").write_text(r.stdout)
        data = json.loads(r.stdout.strip().splitlines()[-1])
    return {int(t["seed"]): t for t in data["results"] if int(t["seed"]) in seeds}


def compare(rows: list[dict[str, Any]], ip: dict[int, dict[str, Any]]) -> None:
    """The two runners side by side, seed by seed, and the counts."""
    print("| seed | MAVSDK: found, error m, confidence, held, time s | in-process: found, error m, confidence, held, "
          "time s, cause |")
    print("|---|---|---|")
    for r in rows:
        t = ip.get(r["seed"])
        mav = (f"{'yes' if r['found'] else 'no'}, {_f(r['error_m'], '.2f')}, {_f(r['confidence'], '.2f')}, "
               f"{'-' if r['held'] is None else ('yes' if r['held'] else 'no')}, {_f(r['time_s'], '.0f')}")  # fmt: skip
        if t is None:
            print(f"| {r['seed']} | {mav} | - |")
            continue
        decl = t.get("declared_ned") is not None
        held = t.get("credible_contains")
        inp = (f"{'yes' if t['success'] else 'no'}, {_f(t['error_m'] if decl else None, '.2f')}, "
               f"{_f(t['confidence'] if decl else None, '.2f')}, {'-' if held is None else ('yes' if held else 'no')}, "
               f"{_f(t['time_s'] if decl else None, '.0f')}, {t.get('cause') or 'declared'}")  # fmt: skip
        print(f"| {r['seed']} | {mav} | {inp} |")
    ok = sum(bool(t["success"]) for t in ip.values())
    held = [bool(t["credible_contains"]) for t in ip.values() if t.get("credible_contains") is not None]
    print(f"in-process: found {ok} / {len(ip)}, declared {len(held)}, region held {sum(held)} / {len(held)}; "
          f"MAVSDK: found {sum(r['found'] for r in rows)} / {len(rows)}")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1000-1009", help="A-B or a,b,c (default 1000-1009: evaluation seeds)")
    ap.add_argument("--scenario", default="paper-s4")
    ap.add_argument("--strategy", default="infotaxis")
    ap.add_argument("--params", default="mission/strategy_files/urban.toml", help="strategy file ('' for none)")
    ap.add_argument("--speed", type=float, default=3.0, help="simulation s per wall s (default 3)")
    ap.add_argument("--wall-limit", type=float, default=600.0, help="the demo's --wall-limit per seed, s")
    ap.add_argument("--max-load", type=float, default=None, help="before each seed wait for the 1-min load average "
                    "to fall below this (at most --load-wait s)")  # fmt: skip
    ap.add_argument("--load-wait", type=float, default=300.0, help="longest wait for --max-load, s (default 300)")
    ap.add_argument("--no-rrd", action="store_true", help="no Rerun recording (the .tlog is kept)")
    ap.add_argument("--keep", default=None, help="keep every seed's logs under this directory")
    ap.add_argument("--from", dest="from_dir", default=None, help="do not fly: the figures from a --keep directory")
    ap.add_argument("--replay-estimator", action="store_true", help="with --from: feed each seed's tlog to the "
                    "estimator offline and print its model-fit verdict")  # fmt: skip
    ap.add_argument("--inprocess", action="store_true", help="also run the in-process runner on the same seeds")
    ap.add_argument("--inprocess-json", default=None, metavar="FILE", help="a saved `windseek search --json` output "
                    "to compare with (instead of running it)")  # fmt: skip
    args = ap.parse_args()
    if not (math.isfinite(args.speed) and args.speed > 0):
        ap.error(f"--speed {args.speed}: must be > 0")
    if args.params:  # the processes run in the repository: a path from here, else from there
        f = next((f for f in (Path(args.params), REPO / args.params) if f.is_file()), None)
        if f is None:
            ap.error(f"--params {args.params}: no such strategy file")
        args.params = str(f.resolve())
    seeds = _seeds(args.seeds)
    root = Path(args.from_dir or args.keep or tempfile.mkdtemp(prefix="mavsdk_search_"))
    print(f"{args.strategy} ({args.params or 'defaults'}) on {args.scenario} through the MAVSDK runner (windseek demo "
          f"--speed {args.speed:g}); logs in {root}; load {os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
    rows = []
    for seed in seeds:
        out = root / f"seed{seed}"
        r = row(seed, args.strategy, out) if args.from_dir else fly(seed, args, out)
        rows.append(r)
        print(json.dumps(r), flush=True)
    print_rows(rows)
    totals(rows)
    if args.from_dir and args.replay_estimator:
        for seed in seeds:
            print(f"seed {seed}: the estimator replayed offline: {replay_estimator(root / f'seed{seed}')}", flush=True)
    if args.inprocess or args.inprocess_json:
        compare(rows, inprocess(args, seeds, root))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
