"""Lockstep speed of PX4 SITL with windseek as its simulator, and PX4's own SIH in the same run.

Per round, one run after the other, each with PX4 hovering at 10 m after an arm + take-off through
pymavlink on its API link:

1. ``windseek sitl open-field --px4 --px4-free`` (lockstep as fast as PX4 answers: one TCP round
   trip per 4 ms step) + PX4 SITL airframe 10016 with windseek's parameters, no flight log; once
   per ``--windseek-repo`` checkout (default: this one; give two to compare a change with its base
   in the same session: ``--windseek-repo . --windseek-repo /path/to/main``);
2. the peer: PX4 SITL airframe 10040 (SIH, PX4's own quad physics inside the PX4 process, same
   250 Hz lockstep step) with ``PX4_SIM_SPEED_FACTOR=1000`` (as fast as PX4 runs), no flight log.

``--rounds R`` repeats that sequence (interleaved, so the machine's load falls on every variant
alike). Printed per run, over ``--windows`` windows of ``--seconds`` wall seconds in hover: the
speed (simulated seconds per wall second, from PX4's own clock on its telemetry) of each window,
the CPU each process used per 4 ms step (user + system, all threads; PX4 runs its modules on
several threads, so its CPU per step can exceed its wall time per step) and the load average;
for the windseek runs also windseek's own split of the lockstep wall time per step (its step and
send vs. waiting for PX4's answer, from ``--exit-summary``, over the whole lockstep run: boot,
take-off, hover). At the end: per variant the median speed over all windows with its range, and
the ratio to SIH. The speeds depend on the machine's load (2 shared cores here); the CPU per step
much less.

Usage: ``WINDSEEK_PX4_BIN=.../bin/px4 python benchmarks/px4_lockstep.py [--seconds 10] [--windows 3]
[--rounds 1] [--windseek-repo PATH ...] [--no-sih]``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from toolchain import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from sitl.hil.px4_params import px4_env  # noqa: E402
from sitl.hil.px4_process import Px4Sitl, free_instance, ports, px4_binary  # noqa: E402

STEP_S = 0.004
HOME_ALT_M = 488.0


def cpu_s(pid: int) -> tuple[float, float]:
    """User and system CPU seconds of a process (all threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    tck = os.sysconf("SC_CLK_TCK")
    return int(fields[11]) / tck, int(fields[12]) / tck


class _Telemetry:
    """PX4's API link read continuously in a thread (a socket read only now and then holds a backlog of
    old messages): the newest PX4 time, relative altitude and system id; PX4's answers (mission protocol,
    COMMAND_ACK) queued for :meth:`upload_mission` and :meth:`command_ack`, its STATUSTEXT and the mission
    items it reports reached kept."""

    REPLIES = ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "COMMAND_ACK")

    def __init__(self, api_port: int) -> None:
        from pymavlink import mavutil

        self.m = mavutil.mavlink_connection(f"udpout:127.0.0.1:{api_port}", source_system=245, source_component=190)
        self.t_px4 = -1.0
        self.alt = 0.0
        self.home_amsl: float | None = None  # the vehicle's own home (SIH's is its SIH_LOC_H0, not windseek's)
        self.sysid: int | None = None
        self.custom_mode = 0  # PX4's mode in its heartbeat: main mode in bits 16-23, sub mode in 24-31
        self.text: list[str] = []
        self.acks: list[tuple[float, int, int]] = []  # (PX4 time s, command, result) of every COMMAND_ACK
        self.reached: list[tuple[float, int]] = []  # (PX4 time s, mission item seq)
        self._replies: deque[Any] = deque(maxlen=200)
        self._cv = threading.Condition()
        self._send_lock = threading.Lock()  # pymavlink's connection is not thread-safe for sending
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        hb = 0.0
        while not self._stop.is_set():
            if time.monotonic() - hb > 0.5:
                hb = time.monotonic()
                self.send("heartbeat_send", 6, 8, 0, 0, 4)  # a ground station: PX4 keeps streaming to us
            msg = self.m.recv_match(blocking=True, timeout=0.1)
            if msg is None:
                continue
            kind = msg.get_type()
            if kind == "GLOBAL_POSITION_INT":
                self.t_px4, self.alt = msg.time_boot_ms * 1e-3, msg.relative_alt * 1e-3
                self.home_amsl = (msg.alt - msg.relative_alt) * 1e-3
            elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                self.sysid, self.custom_mode = msg.get_srcSystem(), int(msg.custom_mode)
            elif kind == "STATUSTEXT":
                self.text.append(msg.text)
            elif kind == "MISSION_ITEM_REACHED":
                self.reached.append((self.t_px4, int(msg.seq)))
            elif kind in self.REPLIES:
                if kind == "COMMAND_ACK":
                    self.acks.append((self.t_px4, int(msg.command), int(msg.result)))
                with self._cv:
                    self._replies.append(msg)
                    self._cv.notify_all()

    def send(self, fn: str, *args: Any) -> None:
        with self._send_lock:
            getattr(self.m.mav, fn)(*args)

    def command(self, cmd: int, *params: float) -> None:
        if self.sysid is not None:
            self.send("command_long_send", self.sysid, 1, cmd, 0, *params, *[0.0] * (7 - len(params)))

    def wait(self, types: list[str] | str, timeout_s: float, cond: Any = None) -> Any:
        """The next queued answer of ``types`` (satisfying ``cond``) within ``timeout_s``, None if none came."""
        from sitl.ardupilot.gcs import next_answer

        return next_answer(self._cv, self._replies, types, timeout_s, cond)

    def clear(self) -> None:
        """Forget the answers queued so far (before a request whose answer to wait for)."""
        with self._cv:
            self._replies.clear()

    def command_ack(self, cmd: int, *params: float, timeout_s: float = 5.0) -> int | None:
        """COMMAND_LONG; its COMMAND_ACK result (None if none came)."""
        self.clear()
        self.command(cmd, *params)
        ack = self.wait("COMMAND_ACK", timeout_s, lambda a: a.command == cmd)
        return None if ack is None else int(ack.result)

    def upload_mission(self, items: list[tuple[float, ...]], timeout_s: float = 20.0) -> int | None:
        """A PX4 mission: ``items`` as :func:`sitl.ardupilot.gcs.upload_items` takes them (item 0 is flown: PX4
        keeps no home item in its mission); the MISSION_ACK type (None if PX4 fell silent)."""
        from sitl.ardupilot.gcs import upload_items

        if self.sysid is None:
            return None
        self.clear()
        return upload_items(self.send, self.wait, self.sysid, items, timeout_s)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.m.close()


def _window(tel: _Telemetry, seconds: float, pids: list[int]) -> dict[str, Any]:
    t0, c0, w0, load0 = tel.t_px4, [cpu_s(p) for p in pids], time.monotonic(), os.getloadavg()[0]
    time.sleep(seconds)
    t1, c1, w1 = tel.t_px4, [cpu_s(p) for p in pids], time.monotonic()
    steps = max(1.0, (t1 - t0) / STEP_S)
    cpu = [(1e6 * (b[0] - a[0]) / steps, 1e6 * (b[1] - a[1]) / steps) for a, b in zip(c0, c1, strict=True)]
    return {"speed": (t1 - t0) / (w1 - w0), "cpu_us_per_step": cpu, "load": (load0 + os.getloadavg()[0]) / 2}


def fly_and_measure(api_port: int, seconds: float, windows: int, pids: list[int]) -> list[dict[str, Any]]:
    """Arm and take off to 10 m (retried: PX4's preflight checks may need a while), wait for the hover,
    then measure ``windows`` windows of ``seconds`` wall seconds."""
    tel = _Telemetry(api_port)
    try:
        end = time.monotonic() + 240.0
        sent = -1e9
        while tel.alt < 9.0:
            if time.monotonic() > end:
                raise RuntimeError("PX4 did not take off to 10 m within 240 s")
            if tel.alt < 0.5 and time.monotonic() - sent > 10.0 and tel.t_px4 > 10.0:
                home = HOME_ALT_M if tel.home_amsl is None else tel.home_amsl
                tel.command(400, 1, 0, 0, 0, 0, 0, 0)  # arm
                tel.command(22, 0, 0, 0, float("nan"), float("nan"), float("nan"), home + 10.0)  # take off
                sent = time.monotonic()
            time.sleep(0.2)
        time.sleep(3.0)  # settle in hover
        return [_window(tel, seconds, pids) for _ in range(windows)]
    finally:
        tel.close()


def run_windseek(binary: Path, repo: Path, seconds: float, windows: int, tmp: Path) -> dict[str, Any]:
    n = free_instance()
    p = ports(n)
    tag = f"{repo.name}-{n}-{time.monotonic_ns()}"
    summary = tmp / f"windseek-{tag}.json"
    log = open(tmp / f"windseek-{tag}.log", "wb")  # noqa: SIM115 - closed below
    ws = subprocess.Popen([sys.executable, "-m", "windseek.cli", "sitl", "open-field", "--px4", "--px4-port",
                           str(p["sim"]), "--px4-free", "--exit-summary", str(summary)], cwd=repo, stdout=log,
                          stderr=subprocess.STDOUT)  # fmt: skip
    px4 = Px4Sitl(binary, n, tmp / f"px4-{tag}", tmp / f"px4-{tag}.log", speed=20.0).start()
    try:
        assert px4.proc is not None
        wins = fly_and_measure(p["api"], seconds, windows, [ws.pid, px4.proc.pid])
    finally:
        ws.send_signal(signal.SIGTERM)
        ws.wait(20)
        px4.stop()
        log.close()
    s = json.loads(summary.read_text()) if summary.exists() else {}
    return {"windows": wins, "split": [s.get("lockstep_us_per_step_windseek"), s.get("lockstep_us_per_step_px4")]}


def run_sih(binary: Path, seconds: float, windows: int, tmp: Path) -> dict[str, Any]:
    n = free_instance()
    timeouts = {k: v for k, v in px4_env(20.0).items() if k.endswith("_LOSS_T")}
    px4 = Px4Sitl(binary, n, tmp / f"px4-sih-{n}", tmp / f"px4-sih-{n}.log", sih=True,
                  extra_env={"PX4_SIM_SPEED_FACTOR": "1000", **timeouts}).start()  # fmt: skip
    try:
        assert px4.proc is not None
        return {"windows": fly_and_measure(ports(n)["api"], seconds, windows, [px4.proc.pid])}
    finally:
        px4.stop()


def _cpu(c: tuple[float, float]) -> str:
    return f"{c[0] + c[1]:.0f} us (user {c[0]:.0f} + sys {c[1]:.0f})"


def _report(label: str, r: dict[str, Any]) -> None:
    speeds = " ".join(f"{w['speed']:.2f}x" for w in r["windows"])
    cpus = [w["cpu_us_per_step"] for w in r["windows"]]
    mean = [(statistics.fmean(c[i][0] for c in cpus), statistics.fmean(c[i][1] for c in cpus))
            for i in range(len(cpus[0]))]  # fmt: skip
    names = ["windseek", "PX4"] if len(mean) == 2 else ["PX4"]
    cpu = "; ".join(f"{n} {_cpu(c)}" for n, c in zip(names, mean, strict=True))
    load = statistics.fmean(w["load"] for w in r["windows"])
    line = f"{label}: {speeds} real time; CPU per 4 ms step: {cpu}; load {load:.1f}"
    if r.get("split") and r["split"][0] is not None:
        line += f"; lockstep wall per step: windseek {r['split'][0]:.0f} us, waiting for PX4 {r['split'][1]:.0f} us"
    print(line, flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="wall seconds per measurement window (default 10)")
    ap.add_argument("--windows", type=int, default=3, help="measurement windows per run (default 3)")
    ap.add_argument("--rounds", type=int, default=1, help="repeat every variant this many times, interleaved")
    ap.add_argument("--windseek-repo", action="append", type=Path, metavar="PATH",
                    help="a windseek checkout whose `windseek sitl` to run (repeatable; default: this one)")
    ap.add_argument("--no-sih", action="store_true", help="skip the PX4 SIH peer")
    args = ap.parse_args()
    binary = px4_binary()
    if binary is None:
        print("set WINDSEEK_PX4_BIN to a PX4 SITL binary (build/px4_sitl_*/bin/px4)", file=sys.stderr)
        return 2
    repos = [p.resolve() for p in (args.windseek_repo or [REPO])]
    tmp = Path(tempfile.mkdtemp(prefix="px4_lockstep_"))
    speeds: dict[str, list[float]] = {}
    for k in range(args.rounds):
        for repo in repos:
            label = f"PX4 + windseek {repo} (lockstep over TCP), round {k + 1}"
            r = run_windseek(binary, repo, args.seconds, args.windows, tmp)
            _report(label, r)
            speeds.setdefault(f"PX4 + windseek {repo}", []).extend(w["speed"] for w in r["windows"])
        if not args.no_sih:
            r = run_sih(binary, args.seconds, args.windows, tmp)
            _report(f"PX4 SIH (peer, PX4's own physics), round {k + 1}", r)
            speeds.setdefault("PX4 SIH", []).extend(w["speed"] for w in r["windows"])
    sih = statistics.median(speeds["PX4 SIH"]) if "PX4 SIH" in speeds else None
    for name, v in speeds.items():
        med = statistics.median(v)
        ratio = f"; / SIH {med / sih:.2f}" if sih and name != "PX4 SIH" else ""
        print(f"{name}: median {med:.2f}x real time (range {min(v):.2f}-{max(v):.2f}, {len(v)} windows){ratio}")
    print(f"logs in {tmp}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
