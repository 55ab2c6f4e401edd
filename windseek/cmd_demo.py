"""``windseek demo``: SITL, wind estimator and MAVSDK search mission as three processes talking MAVLink.

The orchestrator only starts and watches the same commands a user would run against a real
vehicle (each with ``sys.executable -m windseek.cli``), on free local UDP ports::

    windseek sitl SCENARIO --udp 127.0.0.1:E 127.0.0.1:M 127.0.0.1:O --forward --tlog .. --rrd .. --exit-summary ..
    windseek estimator --connect udpin://127.0.0.1:E          (WIND_COV back to the SITL, forwarded to M)
    windseek mission --connect udpin://127.0.0.1:M --strategy S --wind mavlink --json

and listens itself on O (it never sends a HEARTBEAT, so it does not count as a ground station).
It shows progress, waits for the mission to end, stops the SITL and the estimator with SIGTERM
(they close their links and write their logs), and prints the summary: source found (declared
within ``SUCCESS_RADIUS_M`` = 5 m of the true source, horizontally), the declared-position
error, time, path length and the wind RMSE of the estimator's WIND_COV against the simulator's
truth. Files, beside each other in ``--logs`` (default ``logs/``)::

    <UTC time>-<scenario>-<strategy>.rrd     Rerun recording (open with ``rerun FILE``)
    <UTC time>-<scenario>-<strategy>.tlog    every MAVLink frame the SITL sent and received
    <UTC time>-<scenario>-<strategy>.json    the summary (mission result + the SITL's truth figures)
    <UTC time>-<scenario>-<strategy>.{sitl,estimator,mission}.log   each process's own output

The mission publishes its strategy state (STATUSTEXT ``state: NAME``) and its declaration
(NAMED_VALUE_FLOAT SRC_N/E/D/CONF, :mod:`wire.names`) over MAVLink itself; the SITL records
them (.rrd, .tlog, the exit summary's ``declared``). The demo only shows the mission's lines.
Exit status: 0 source found, 1 not found, 2 a process failed (its last lines shown).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import deque
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TextIO

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


def free_udp_port() -> int:
    """An ephemeral local UDP port that is free now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Proc:
    """One child process: its output goes to a log file and a tail kept for error messages."""

    def __init__(self, name: str, cmd: list[str], log_path: Path, on_line: Any = None,
                 stdout_path: Path | None = None) -> None:  # fmt: skip
        self.name = name
        self.cmd = cmd
        self.log_path = log_path
        self.tail: deque[str] = deque(maxlen=20)
        self.on_line = on_line
        self._log: TextIO = open(log_path, "w")  # noqa: SIM115 - closed in close()
        self._stdout: TextIO | None = open(stdout_path, "w") if stdout_path else None  # noqa: SIM115
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.popen = subprocess.Popen(cmd, stdout=self._stdout or subprocess.PIPE,
                                      stderr=subprocess.PIPE if self._stdout else subprocess.STDOUT,
                                      text=True, env=env, start_new_session=True)  # fmt: skip
        self.first_line = threading.Event()
        self._reader = threading.Thread(target=self._read, name=f"read-{name}", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        stream = self.popen.stderr if self._stdout else self.popen.stdout
        for line in stream:
            line = line.rstrip("\n")
            self._log.write(line + "\n")
            self._log.flush()
            self.tail.append(line)
            self.first_line.set()
            if self.on_line is not None:
                with contextlib.suppress(Exception):  # a display problem must not stop the reader
                    self.on_line(line)

    def wait_for(self, pred: Any, timeout_s: float) -> bool:
        """Wait until ``pred()`` or the process exits or the timeout; True if ``pred()``."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if pred():
                return True
            if self.popen.poll() is not None:
                return bool(pred())
            time.sleep(0.1)
        return False

    def stop(self, timeout_s: float = 15.0) -> int | None:
        """SIGTERM (clean shutdown: links closed, logs written), then SIGKILL after ``timeout_s``."""
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5.0)
        self._reader.join(timeout=5.0)
        return self.popen.returncode

    def close(self) -> None:
        self._log.close()
        if self._stdout is not None:
            self._stdout.close()

    def failure(self) -> str:
        lines = "\n".join(f"    {x}" for x in list(self.tail)[-8:])
        return f"{self.name} exited with status {self.popen.returncode}; its last lines ({self.log_path}):\n{lines}"


class Observer(threading.Thread):
    """A passive UDP peer of the SITL (it never sends): follows the vehicle for the progress display."""

    def __init__(self) -> None:
        super().__init__(name="demo-observer", daemon=True)
        from wire.dialect import mavlink as mav

        self.mav = mav
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.sitl_addr: tuple[str, int] | None = None
        self.t = 0.0
        self.pos = [0.0, 0.0, 0.0]
        self.armed = False
        self.mode = ""
        self.chem = 0.0
        self.wind: list[float] | None = None
        self.wind_covs = 0
        self.t_arm: float | None = None
        self._halt = threading.Event()

    def run(self) -> None:
        while not self._halt.is_set():
            try:
                data, addr = self.sock.recvfrom(65536)
            except (TimeoutError, OSError):
                continue
            try:
                msgs = self.parser.parse_buffer(data) or []
            except Exception:  # noqa: BLE001
                continue
            for m in msgs:
                self._on(m, addr)

    def _on(self, m: Any, addr: tuple[str, int]) -> None:
        mtype = m.get_type()
        if m.get_srcSystem() == 1 and m.get_srcComponent() == 1:
            self.sitl_addr = addr
        if mtype == "LOCAL_POSITION_NED":
            self.t = m.time_boot_ms * 1e-3
            self.pos = [m.x, m.y, m.z]
        elif mtype == "HEARTBEAT" and m.get_srcComponent() == 1:
            from wire.px4_modes import name as px4_mode_name

            armed = bool(m.base_mode & 128)
            if armed and not self.armed:
                self.t_arm = self.t
            self.armed = armed
            self.mode = px4_mode_name(m.custom_mode)
        elif mtype == "NAMED_VALUE_FLOAT" and str(m.name).rstrip("\x00") == "CHEM":
            self.chem = float(m.value)
        elif mtype == "WIND_COV":
            self.wind = [m.wind_x, m.wind_y, m.wind_z]
            self.wind_covs += 1

    def status(self) -> str:
        from recording.sim_hook import wind_speed_from_deg

        n, e, d = self.pos
        s = f"t {self.t:6.1f} s  {self.mode or '-':12s} N {n:+6.1f} E {e:+6.1f} alt {-d:4.1f} m  chem {self.chem:6.2f}"
        if self.wind is not None:
            sp, fr = wind_speed_from_deg(self.wind)
            s += f"  wind est {sp:4.1f} m/s from {fr:3.0f} deg"
        return s

    def close(self) -> None:
        self._halt.set()
        self.join(timeout=2.0)
        self.sock.close()


def _windseek(*args: str) -> list[str]:
    return [sys.executable, "-m", "windseek.cli", *args]


def run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from mission.safety import SafetyLimits
    from mission.strategies import STRATEGIES
    from sitl.scenario import load_scenario

    if args.strategy not in STRATEGIES:
        raise ValueError(f"--strategy {args.strategy!r}: choose one of {', '.join(sorted(STRATEGIES))}")
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ValueError(f"--speed {args.speed}: must be > 0")
    sc = load_scenario(args.scenario)  # fails early, with the scenario's own message
    seed = sc.seed if args.seed is None else int(args.seed)
    limits = SafetyLimits()
    time_limit = limits.time_limit_s if args.time_limit is None else float(args.time_limit)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    logs = Path(args.logs)
    logs.mkdir(parents=True, exist_ok=True)
    base = logs / f"{stamp}-{sc.name}-{args.strategy}"
    files = {k: Path(f"{base}.{k}") for k in ("rrd", "tlog", "json") if not (k == "rrd" and args.no_rrd)}
    rrd_args = [] if args.no_rrd else ["--rrd", str(files["rrd"]), "--rrd-strategy", args.strategy]
    truth_path = Path(f"{base}.truth.json")
    console = Console(stderr=True)
    live = console.is_terminal

    def note(text: str) -> None:
        console.print(text, highlight=False, markup=False)

    p_est, p_mis = free_udp_port(), free_udp_port()
    obs = Observer()
    obs.start()
    fence = ",".join(f"{v:g}" for v in (*limits.box_min_ned, *limits.box_max_ned))
    procs: list[Proc] = []
    wall0 = time.monotonic()

    def on_mission_line(line: str) -> None:
        if line.startswith("mission: "):  # not MAVSDK's own debug lines, nor the autopilot's echoed STATUSTEXT
            note(f"  {line}")

    note(f"windseek demo: {sc.name} / {args.strategy} / seed {seed} / speed {args.speed:g}; logs {base}.*")
    try:
        sitl = Proc("sitl", _windseek("sitl", args.scenario, "--speed", f"{args.speed:g}", "--seed", str(seed),
                                      "--udp-bind", "127.0.0.1:0",
                                      "--udp", f"127.0.0.1:{p_est}", f"127.0.0.1:{p_mis}", f"127.0.0.1:{obs.port}",
                                      "--forward", "--tlog", str(files["tlog"]), *rrd_args, f"--geofence={fence}",
                                      "--exit-summary", str(truth_path)),
                    Path(f"{base}.sitl.log"))  # fmt: skip
        procs.append(sitl)
        est = Proc("estimator", _windseek("estimator", "--connect", f"udpin://127.0.0.1:{p_est}",
                                          "--imu-average", str(args.imu_average), "--progress-every", "5",
                                          "--link-timeout", "30"),
                   Path(f"{base}.estimator.log"))  # fmt: skip
        procs.append(est)
        cols = (TextColumn("{task.description}"), BarColumn(bar_width=24), TextColumn("{task.fields[status]}"),
                TimeElapsedColumn())  # fmt: skip
        with Progress(*cols, console=console, transient=False, disable=not live) as bar:
            task = bar.add_task("starting", total=time_limit, status="")

            def show(phase: str) -> None:
                done = 0.0 if obs.t_arm is None else min(time_limit, obs.t - obs.t_arm)
                bar.update(task, description=phase, completed=done, status=obs.status())

            # 1. the SITL streams (its clock runs from here: the vehicle waits on the ground)
            show("starting the SITL (first run: numba compiles for ~20 s)")
            if not sitl.wait_for(lambda: obs.sitl_addr is not None, 120.0):
                raise _FailedError(sitl, "the SITL did not start streaming within 120 s")
            note(f"  SITL streaming ({sitl.tail[0] if sitl.tail else ''})")
            # 2. the estimator receives its inputs (it publishes WIND_COV once the vehicle is in the air)
            show("waiting for the estimator")
            if not est.wait_for(lambda: any("inputs:" in x for x in est.tail), 150.0):
                raise _FailedError(est, "the estimator did not receive its inputs within 150 s")
            note(f"  estimator ready ({next(x for x in est.tail if 'inputs:' in x)})")
            # 3. the mission
            mis_cmd = _windseek("mission", "--connect", f"udpin://127.0.0.1:{p_mis}", "--strategy", args.strategy,
                                "--wind", "mavlink", "--speed-hint", f"{args.speed:g}", "--seed", str(seed),
                                "--time-limit", f"{time_limit:g}", "--json")  # fmt: skip
            mis = Proc("mission", mis_cmd, Path(f"{base}.mission.log"), on_line=on_mission_line,
                       stdout_path=Path(f"{base}.mission.json"))  # fmt: skip
            procs.append(mis)
            last_line = time.monotonic()
            while mis.popen.poll() is None:
                if time.monotonic() - wall0 > args.wall_limit:
                    raise _FailedError(mis, f"the mission did not end within --wall-limit {args.wall_limit:g} s")
                for p in (sitl, est):
                    if p.popen.poll() is not None:
                        raise _FailedError(p, f"{p.name} stopped during the mission")
                phase = "searching" if obs.mode == "OFFBOARD" else ("flying" if obs.armed else "mission")
                show(phase)
                if not live and time.monotonic() - last_line > 10.0:
                    last_line = time.monotonic()
                    note(f"  [{time.monotonic() - wall0:5.0f} s] {obs.status()}")
                time.sleep(0.2)
            show("mission ended")
        mis.stop()
        mission = _read_json(Path(f"{base}.mission.json"))
        if mission is None:
            raise _FailedError(mis, "the mission printed no result")
        est.stop()
        rc_sitl = sitl.stop()
        truth = _read_json(truth_path)
        if truth is None:
            raise _FailedError(sitl, f"the SITL wrote no exit summary (status {rc_sitl})")
    except _FailedError as f:
        for p in procs:
            p.stop(5.0)
        note(f"windseek demo: error: {f.why}")
        note(f.proc.failure())
        return 2
    finally:
        for p in procs:
            if p.popen.poll() is None:
                p.stop(5.0)
            p.close()
        obs.close()
    wall_s = time.monotonic() - wall0
    summary = make_summary(sc.name, args.strategy, seed, args.speed, mission, truth, wall_s, files)
    files["json"].write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n")
    if "rrd" in files:
        try:  # the recording carries the same summary as the one printed (and the .json)
            from recording.finalize import add_demo_result

            add_demo_result(files["rrd"], summary)
        except (OSError, RuntimeError, ValueError) as e:
            note(f"  recording: the summary could not be added to {files['rrd']}: {e}")
    with contextlib.suppress(OSError):
        truth_path.unlink()
    print_summary(summary, note)
    if args.json:
        print(json.dumps(summary, allow_nan=False), flush=True)
    return 0 if summary["found"] else 1


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
    declared = mission.get("declared_ned")
    sources = truth.get("true_sources_ned_m") or []
    err = None
    if declared and sources:
        err = min(math.hypot(declared[0] - s[0], declared[1] - s[1]) for s in sources)
    cause = mission.get("cause", "")
    found = cause == "declared" and err is not None and err <= SUCCESS_RADIUS_M
    if found:
        reason = f"declared {err:.1f} m from the true source"
    elif cause != "declared":
        reason = f"mission ended without a declaration: {cause or 'unknown'}"
    else:
        reason = f"declared {err:.1f} m from the true source (more than {SUCCESS_RADIUS_M:g} m)"
    return {
        "scenario": scenario, "strategy": strategy, "seed": seed, "speed": speed,
        "found": bool(found), "reason": reason, "cause": cause,
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
