"""``windseek demo``: SITL, wind estimator and MAVSDK search mission as three processes talking MAVLink.

The orchestrator only starts and watches the same commands a user would run against a real
vehicle (each with ``sys.executable -m windseek.cli``), on free local UDP ports::

    windseek sitl SCENARIO --udp 127.0.0.1:E 127.0.0.1:M 127.0.0.1:O --forward --tlog .. --rrd .. --exit-summary ..
    windseek estimator --connect udpin://127.0.0.1:E          (WIND_COV back to the SITL, forwarded to M)
    windseek mission --connect udpin://127.0.0.1:M --strategy S [--params FILE] --wind mavlink --json

and listens itself on O (it never sends a HEARTBEAT, so it does not count as a ground station).
It shows progress, waits for the mission to end, stops the SITL and the estimator with SIGTERM
(they close their links and write their logs), and prints the summary: source found (declared
within the strategy's success radius of the true source, horizontally: 3 m for infotaxis, whose
confidence is stated for 3 m, ``SUCCESS_RADIUS_M`` = 5 m for the others, as in ``windseek search``),
the declared-position error, time, path length and the wind RMSE of the estimator's WIND_COV against the simulator's
truth. Files, beside each other in ``--logs`` (default ``logs/``)::

    <UTC time>-<scenario>-<strategy>.rrd     Rerun recording (open with ``rerun FILE``)
    <UTC time>-<scenario>-<strategy>.tlog    every MAVLink frame the SITL sent and received
    <UTC time>-<scenario>-<strategy>.json    the summary (mission result + the SITL's truth figures)
    <UTC time>-<scenario>-<strategy>.{sitl,estimator,mission}.log   each process's own output

The mission publishes its strategy state (STATUSTEXT ``state: NAME``) and its declaration
(NAMED_VALUE_FLOAT SRC_N/E/D/CONF, :mod:`wire.names`) over MAVLink itself; the SITL records
them (.rrd, .tlog, the exit summary's ``declared``). The mission also writes its own recording
(``--rrd <base>.mission.rrd``: the strategy's posterior and credible circle, the setpoints), which
the demo merges into the SITL's ``.rrd`` at the end (:mod:`recording.finalize`) and then deletes.
The demo only shows the mission's lines.
Exit status: 0 source found, 1 not found, 2 a process failed (its last lines shown).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from windseek.demo_parts import Observer, Proc, free_udp_port

SUCCESS_RADIUS_M = 5.0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="SITL + wind estimator + MAVSDK search mission as three MAVLink processes, with a Rerun log",
        description="Start windseek sitl, windseek estimator and windseek mission as separate processes talking "
        "MAVLink over local UDP, show progress, print a summary and write logs/<time>-<scenario>-<strategy>.rrd, "
        ".tlog and .json. Exit 0 when the source was found.",
    )
    p.add_argument("--scenario", default="open-field", help="scenario name or .toml (default open-field)")
    p.add_argument("--strategy", default="surge-cast", help="search strategy (default surge-cast)")
    p.add_argument("--params", default=None, metavar="FILE", help="strategy file given to the mission (TOML "
                   "with a [strategy] table, e.g. mission/strategy_files/urban.toml; default: the strategy's defaults)")
    p.add_argument("--speed", type=float, default=5.0,
                   help="simulation seconds per wall second (default 5: a search in well under a minute)")
    p.add_argument("--seed", type=int, default=None, help="simulation and strategy seed (default: the scenario's)")
    p.add_argument("--time-limit", type=float, default=None, metavar="S",
                   help="mission time limit, vehicle seconds (default: the mission's)")
    p.add_argument("--logs", default="logs", metavar="DIR", help="folder for the logs (default ./logs)")
    p.add_argument("--imu-average", type=int, default=2, metavar="N",
                   help="IMU samples the estimator averages per filter step (default 2)")
    p.add_argument("--wall-limit", type=float, default=300.0, metavar="S",
                   help="give up after this many wall seconds (default 300)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    p.add_argument("--no-rrd", action="store_true",
                   help="write no Rerun recording (the .tlog and .json are still written)")
    p.set_defaults(func=run)


def _windseek(*args: str) -> list[str]:
    return [sys.executable, "-m", "windseek.cli", *args]


@dataclass
class _Plan:
    """A checked demo: the scenario, seed, time limit, log files and the geofence box."""

    scenario: str
    name: str
    strategy: str
    params: str | None  # the strategy file the mission flies with (None: the strategy's defaults)
    seed: int
    speed: float
    time_limit: float
    imu_average: int
    wall_limit: float
    base: Path
    files: dict[str, Path]
    truth_path: Path
    fence: str
    buildings: bool  # the scenario has [urban] buildings: the mission flies among them (--buildings)
    search_altitude_m: float  # the mission's search altitude (its strategy's default, within the limits)
    mission_rrd: Path | None  # the mission's own recording, merged into the SITL's at the end (None: no --rrd)


def _plan(args: argparse.Namespace) -> _Plan:
    from mission.safety import SafetyLimits
    from mission.strategies import STRATEGIES
    from mission.strategies.params import load_params
    from sitl.scenario import load_scenario

    if args.strategy not in STRATEGIES:
        raise ValueError(f"--strategy {args.strategy!r}: choose one of {', '.join(sorted(STRATEGIES))}")
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ValueError(f"--speed {args.speed}: must be > 0")
    sc = load_scenario(args.scenario)  # fails early, with the scenario's own message
    params = load_params(args.strategy, args.params)  # a bad strategy file: one line naming it, before any log
    limits = SafetyLimits()
    logs = Path(args.logs)
    logs.mkdir(parents=True, exist_ok=True)
    base = logs / f"{datetime.now(UTC).strftime('%Y%m%dT%H%M%SZ')}-{sc.name}-{args.strategy}"
    return _Plan(
        scenario=args.scenario, name=sc.name, strategy=args.strategy, params=args.params,
        seed=sc.seed if args.seed is None else int(args.seed),
        speed=float(args.speed), time_limit=limits.time_limit_s if args.time_limit is None else float(args.time_limit),
        imu_average=int(args.imu_average), wall_limit=float(args.wall_limit), base=base,
        files={k: Path(f"{base}.{k}") for k in ("rrd", "tlog", "json") if not (k == "rrd" and args.no_rrd)},
        truth_path=Path(f"{base}.truth.json"),
        # The mission's box is about home (the start); the SITL draws it in its local frame.
        fence=",".join(f"{h + v:g}" for h, v in zip((*sc.start.position_ned, *sc.start.position_ned),
                                                     (*limits.box_min_ned, *limits.box_max_ned), strict=True)),
        buildings=sc.urban is not None and bool(sc.urban.buildings),
        search_altitude_m=min(max(params.altitude_m, limits.min_altitude_m),
                              limits.max_altitude_m),
        mission_rrd=None if args.no_rrd else Path(f"{base}.mission.rrd"),
    )  # fmt: skip


def rrd_argv(pl: _Plan) -> list[str]:
    """The SITL's recording arguments in a demo: the file, the strategy's name and the height of the
    urban wind field's slice, the mission's search altitude (the SITL alone knows only the scenario's
    take-off altitude)."""
    if "rrd" not in pl.files:
        return []
    return ["--rrd", str(pl.files["rrd"]), "--rrd-strategy", pl.strategy, "--rrd-altitude", f"{pl.search_altitude_m:g}"]


def mission_argv(pl: _Plan, port: int) -> list[str]:
    """``windseek mission``'s arguments in a demo: the estimator's wind from the network, its own
    recording (the strategy's posterior and the setpoints, merged into the SITL's at the end) and, in a
    scenario with buildings, those buildings as exclusion zones (without them the search flies into
    the first block in its way)."""
    return ["mission", "--connect", f"udpin://127.0.0.1:{port}", "--strategy", pl.strategy,
            *(["--params", pl.params] if pl.params is not None else []), "--wind", "mavlink",
            "--speed-hint", f"{pl.speed:g}", "--seed", str(pl.seed), "--time-limit", f"{pl.time_limit:g}", "--json",
            *(["--rrd", str(pl.mission_rrd)] if pl.mission_rrd is not None else []),
            *(["--buildings", pl.scenario] if pl.buildings else [])]  # fmt: skip


class _Demo:
    """The three processes of one demo, started and watched in order (see the module docstring)."""

    def __init__(self, plan: _Plan, console: Any) -> None:
        self.plan = plan
        self.console = console
        self.live = bool(console.is_terminal)
        self.obs = Observer()
        self.obs.start()
        self.procs: list[Proc] = []
        self.wall0 = time.monotonic()
        self.p_est, self.p_mis = free_udp_port(), free_udp_port()

    def note(self, text: str) -> None:
        self.console.print(text, highlight=False, markup=False)

    def _start(self, name: str, argv: list[str], **kw: Any) -> Proc:
        proc = Proc(name, _windseek(*argv), Path(f"{self.plan.base}.{name}.log"), **kw)
        self.procs.append(proc)
        return proc

    def fly(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """Run SITL, estimator and mission; (the mission's result, the SITL's truth summary)."""
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        pl, obs = self.plan, self.obs
        rrd_args = rrd_argv(pl)
        sitl = self._start("sitl", ["sitl", pl.scenario, "--speed", f"{pl.speed:g}", "--seed", str(pl.seed),
                                    "--udp-bind", "127.0.0.1:0", "--udp", f"127.0.0.1:{self.p_est}",
                                    f"127.0.0.1:{self.p_mis}", f"127.0.0.1:{obs.port}", "--forward",
                                    "--tlog", str(pl.files["tlog"]), *rrd_args, f"--geofence={pl.fence}",
                                    "--exit-summary", str(pl.truth_path)])  # fmt: skip
        est = self._start("estimator", ["estimator", "--connect", f"udpin://127.0.0.1:{self.p_est}",
                                        "--imu-average", str(pl.imu_average), "--progress-every", "5",
                                        "--link-timeout", "30"])  # fmt: skip
        cols = (TextColumn("{task.description}"), BarColumn(bar_width=24), TextColumn("{task.fields[status]}"),
                TimeElapsedColumn())  # fmt: skip
        with Progress(*cols, console=self.console, transient=False, disable=not self.live) as bar:
            task = bar.add_task("starting", total=pl.time_limit, status="")

            def show(phase: str) -> None:
                done = 0.0 if obs.t_arm is None else min(pl.time_limit, obs.t - obs.t_arm)
                bar.update(task, description=phase, completed=done, status=obs.status())

            # 1. the SITL streams (its clock runs from here: the vehicle waits on the ground)
            show("starting the SITL (first run: numba compiles for ~20 s)")
            if not sitl.wait_for(lambda: obs.sitl_addr is not None, 120.0):
                raise _FailedError(sitl, "the SITL did not start streaming within 120 s")
            self.note(f"  SITL streaming ({sitl.tail[0] if sitl.tail else ''})")
            # 2. the estimator receives its inputs (it publishes WIND_COV once the vehicle is in the air)
            show("waiting for the estimator")
            if not est.wait_for(lambda: any("inputs:" in x for x in est.tail), 150.0):
                raise _FailedError(est, "the estimator did not receive its inputs within 150 s")
            self.note(f"  estimator ready ({next(x for x in est.tail if 'inputs:' in x)})")
            # 3. the mission
            mis = self._mission(show, sitl, est)
        return self._collect(mis, sitl, est)

    def _mission(self, show: Any, sitl: Proc, est: Proc) -> Proc:
        pl, obs = self.plan, self.obs

        def on_line(line: str) -> None:
            if line.startswith("mission: "):  # not MAVSDK's debug lines, nor the autopilot's echoed STATUSTEXT
                self.note(f"  {line}")

        if pl.speed > 1.0:
            # PX4's offboard-loss timeout (COM_OF_LOSS_T, 1 s) counts vehicle time: at speed 5 it is 0.2 s of
            # wall clock, less than a scheduling hiccup of a loaded machine. 1 s of wall clock, as in real time.
            loss_t = 1.0 * pl.speed
            if obs.set_param("COM_OF_LOSS_T", loss_t):
                self.note(f"  offboard-loss timeout COM_OF_LOSS_T = {loss_t:g} s of vehicle time (1 s of wall clock)")
        mis = self._start("mission", mission_argv(pl, self.p_mis), on_line=on_line,
                          stdout_path=Path(f"{pl.base}.mission.json"))
        last_line = time.monotonic()
        while mis.popen.poll() is None:
            if time.monotonic() - self.wall0 > pl.wall_limit:
                raise _FailedError(mis, f"the mission did not end within --wall-limit {pl.wall_limit:g} s")
            for p in (sitl, est):
                if p.popen.poll() is not None:
                    raise _FailedError(p, f"{p.name} stopped during the mission")
            show("searching" if obs.mode == "OFFBOARD" else ("flying" if obs.armed else "mission"))
            if not self.live and time.monotonic() - last_line > 10.0:
                last_line = time.monotonic()
                self.note(f"  [{time.monotonic() - self.wall0:5.0f} s] {obs.status()}")
            time.sleep(0.2)
        show("mission ended")
        return mis

    def _collect(self, mis: Proc, sitl: Proc, est: Proc) -> tuple[dict[str, Any], dict[str, Any]]:
        """Stop the processes in order (they close their links and write their logs) and read the results."""
        mis.stop()
        mission = _read_json(Path(f"{self.plan.base}.mission.json"))
        if mission is None:
            raise _FailedError(mis, "the mission printed no result")
        est.stop()
        rc_sitl = sitl.stop()
        truth = _read_json(self.plan.truth_path)
        if truth is None:
            raise _FailedError(sitl, f"the SITL wrote no exit summary (status {rc_sitl})")
        return mission, truth

    def close(self) -> None:
        for p in self.procs:
            if p.popen.poll() is None:
                p.stop(5.0)
            p.close()
        self.obs.close()


def run(args: argparse.Namespace) -> int:
    from rich.console import Console

    plan = _plan(args)
    demo = _Demo(plan, Console(stderr=True))
    demo.note(f"windseek demo: {plan.name} / {plan.strategy}{f' ({plan.params})' if plan.params else ''} / seed "
              f"{plan.seed} / speed {plan.speed:g}; logs {plan.base}.*")  # fmt: skip
    try:
        mission, truth = demo.fly()
    except _FailedError as f:
        for p in demo.procs:
            p.stop(5.0)
        demo.note(f"windseek demo: error: {f.why}")
        demo.note(f.proc.failure())
        return 2
    finally:
        demo.close()
    summary = make_summary(plan.name, plan.strategy, plan.seed, plan.speed, mission, truth,
                           time.monotonic() - demo.wall0, plan.files)  # fmt: skip
    summary["params"] = plan.params
    plan.files["json"].write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n")
    if "rrd" in plan.files:
        _finish_recording(plan, summary, demo.note)
    with contextlib.suppress(OSError):
        plan.truth_path.unlink()
    print_summary(summary, demo.note)
    if args.json:
        print(json.dumps(summary, allow_nan=False), flush=True)
    return 0 if summary["found"] else 1


def _finish_recording(plan: _Plan, summary: dict[str, Any], note: Any) -> None:
    """The SITL's recording gets the summary printed (and the .json) and the mission's own recording
    (the strategy's posterior, the setpoints), which is then deleted: one file to open."""
    from recording.finalize import add_demo_result

    mis = plan.mission_rrd if plan.mission_rrd is not None and plan.mission_rrd.is_file() else None
    try:
        add_demo_result(plan.files["rrd"], summary, mis)
    except (OSError, RuntimeError, ValueError) as e:
        note(f"  recording: the summary could not be added to {plan.files['rrd']}: {e}")
        return
    if mis is not None:
        with contextlib.suppress(OSError):
            mis.unlink()


class _FailedError(Exception):
    def __init__(self, proc: Proc, why: str) -> None:
        super().__init__(why)
        self.proc = proc
        self.why = why


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        text = path.read_text().strip().splitlines()
        return json.loads(text[-1]) if len(text) == 1 else json.loads("\n".join(text))
    except (OSError, ValueError, IndexError):
        return None


def make_summary(scenario: str, strategy: str, seed: int, speed: float, mission: dict[str, Any],
                 truth: dict[str, Any], wall_s: float, files: dict[str, Path]) -> dict[str, Any]:  # fmt: skip
    """The demo's summary (JSON-ready): mission result, truth figures, found or not and why."""
    from mission.runners.inprocess import SUCCESS_RADIUS_BY_STRATEGY

    radius = SUCCESS_RADIUS_BY_STRATEGY.get(strategy, SUCCESS_RADIUS_M)
    declared = mission.get("declared_ned")
    sources = truth.get("true_sources_ned_m") or []
    err = None
    if declared and sources:
        err = min(math.hypot(declared[0] - s[0], declared[1] - s[1]) for s in sources)
    cause = mission.get("cause", "")
    found = cause == "declared" and err is not None and err <= radius
    if found:
        reason = f"declared {err:.1f} m from the true source"
    elif cause != "declared":
        reason = f"mission ended without a declaration: {cause or 'unknown'}"
    else:
        reason = f"declared {err:.1f} m from the true source (more than {radius:g} m)"
    return {
        "scenario": scenario, "strategy": strategy, "seed": seed, "speed": speed,
        "found": bool(found), "success_radius_m": radius, "reason": reason, "cause": cause,
        "declared_ned_m": declared, "confidence": mission.get("confidence"),
        "true_sources_ned_m": sources,
        "declared_error_horizontal_m": None if err is None else round(err, 2),
        "time_to_declaration_s": mission.get("time_s"), "mission_time_s": mission.get("mission_time_s"),
        "wall_time_s": round(wall_s, 1),
        "search_path_m": mission.get("path_m"), "path_length_m": truth.get("path_length_m"),
        "wind_rmse_ned_m_s": truth.get("wind_rmse_ned_m_s"),
        "wind_rmse_horizontal_m_s": truth.get("wind_rmse_horizontal_m_s"),
        "wind_estimates_scored": truth.get("wind_estimates_scored"),
        "landed": mission.get("landed"), "disarmed": mission.get("disarmed"), "crashed": truth.get("crashed"),
        "files": {k: str(v) for k, v in files.items()},
        "mission": mission, "truth": truth,
    }  # fmt: skip


def print_summary(s: dict[str, Any], note: Any) -> None:
    def f(v: Any, fmt: str = ".1f") -> str:
        return "-" if v is None else format(v, fmt)

    d = s["declared_ned_m"]
    src = s["true_sources_ned_m"][0] if s["true_sources_ned_m"] else None
    rm = s["wind_rmse_ned_m_s"] or [None] * 3
    note("")
    note(f"windseek demo summary: {s['scenario']} / {s['strategy']} / seed {s['seed']} / speed {s['speed']:g}")
    note(f"  source found       {'YES' if s['found'] else 'NO'}: {s['reason']}")
    if d:
        note(f"  declared           N {d[0]:.1f} E {d[1]:.1f} m (confidence {f(s['confidence'], '.2f')}); "
             f"true N {f(src and src[0])} E {f(src and src[1])} m; error {f(s['declared_error_horizontal_m'])} m")
    note(f"  time               {f(s['time_to_declaration_s'])} s to the declaration, {f(s['mission_time_s'])} s "
         f"arm to disarm (vehicle time); {s['wall_time_s']:.0f} s wall")
    note(f"  path length        {f(s['search_path_m'])} m searched, {f(s['path_length_m'])} m flown in total")
    note(f"  wind RMSE vs truth N {f(rm[0], '.2f')} E {f(rm[1], '.2f')} D {f(rm[2], '.2f')} m/s "
         f"(horizontal {f(s['wind_rmse_horizontal_m_s'], '.2f')} m/s, {s['wind_estimates_scored']} WIND_COV "
         "while airborne)")
    if "rrd" in s["files"]:
        note(f"  recording          {s['files']['rrd']}   (view: rerun {s['files']['rrd']})")
    note(f"  telemetry log      {s['files']['tlog']}")
    note(f"  summary            {s['files']['json']}")
