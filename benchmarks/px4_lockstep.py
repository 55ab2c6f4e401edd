"""Lockstep speed of PX4 SITL with windseek as its simulator, and PX4's own SIH in the same run.

Two runs, one after the other, each with PX4 hovering at 10 m after an arm + take-off through
pymavlink on its API link:

1. ``windseek sitl open-field --px4 --px4-free`` (lockstep as fast as PX4 answers: one TCP round
   trip per 4 ms step) + PX4 SITL airframe 10016 with windseek's parameters, no flight log;
2. the peer: PX4 SITL airframe 10040 (SIH, PX4's own quad physics inside the PX4 process, same
   250 Hz lockstep step) with ``PX4_SIM_SPEED_FACTOR=1000`` (as fast as PX4 runs), no flight log.

Printed per run, over a window of ``--seconds`` wall seconds in hover: the speed (simulated
seconds per wall second, from PX4's own clock on its telemetry), the CPU each process used per
4 ms step (all threads; PX4 runs its modules on several threads, so its CPU per step can exceed
its wall time per step), and the load average; then the ratio of the two speeds. The speeds
depend on the machine's load (2 shared cores here); the CPU per step much less.

Usage: ``WINDSEEK_PX4_BIN=.../bin/px4 python benchmarks/px4_lockstep.py [--seconds 30]``.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from windseek import numba_cache  # noqa: E402 - before any kernel module

numba_cache.configure()
from sitl.hil.px4_params import px4_env  # noqa: E402
from sitl.hil.px4_process import Px4Sitl, free_instance, ports, px4_binary  # noqa: E402

STEP_S = 0.004
HOME_ALT_M = 488.0


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (all threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class _Telemetry:
    """PX4's API link read continuously in a thread (a socket read only now and then holds a backlog of
    old messages): the newest PX4 time, relative altitude and system id."""

    def __init__(self, api_port: int) -> None:
        from pymavlink import mavutil

        self.m = mavutil.mavlink_connection(f"udpout:127.0.0.1:{api_port}", source_system=245, source_component=190)
        self.t_px4 = -1.0
        self.alt = 0.0
        self.sysid: int | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        hb = 0.0
        while not self._stop.is_set():
            if time.monotonic() - hb > 0.5:
                hb = time.monotonic()
                self.m.mav.heartbeat_send(6, 8, 0, 0, 4)  # a ground station: PX4 keeps streaming to us
            msg = self.m.recv_match(blocking=True, timeout=0.1)
            if msg is None:
                continue
            if msg.get_type() == "GLOBAL_POSITION_INT":
                self.t_px4, self.alt = msg.time_boot_ms * 1e-3, msg.relative_alt * 1e-3
            elif msg.get_type() == "HEARTBEAT" and msg.get_srcComponent() == 1:
                self.sysid = msg.get_srcSystem()

    def command(self, cmd: int, *params: float) -> None:
        if self.sysid is not None:
            self.m.mav.command_long_send(self.sysid, 1, cmd, 0, *params)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.m.close()


def fly_and_measure(api_port: int, seconds: float, pids: list[int]) -> dict[str, Any]:
    """Arm and take off to 10 m (retried: PX4's preflight checks may need a while), wait for the hover,
    then measure over ``seconds`` wall seconds."""
    tel = _Telemetry(api_port)
    try:
        end = time.monotonic() + 240.0
        sent = -1e9
        while tel.alt < 9.0:
            if time.monotonic() > end:
                raise RuntimeError("PX4 did not take off to 10 m within 240 s")
            if tel.alt < 0.5 and time.monotonic() - sent > 10.0 and tel.t_px4 > 10.0:
                tel.command(400, 1, 0, 0, 0, 0, 0, 0)  # arm
                tel.command(22, 0, 0, 0, float("nan"), float("nan"), float("nan"), HOME_ALT_M + 10.0)  # take off
                sent = time.monotonic()
            time.sleep(0.2)
        time.sleep(3.0)  # settle in hover
        t0, c0, w0, load0 = tel.t_px4, [cpu_s(p) for p in pids], time.monotonic(), os.getloadavg()[0]
        time.sleep(seconds)
        t1, c1, w1 = tel.t_px4, [cpu_s(p) for p in pids], time.monotonic()
    finally:
        tel.close()
    steps = max(1.0, (t1 - t0) / STEP_S)
    return {"speed": (t1 - t0) / (w1 - w0), "sim_s": t1 - t0, "wall_s": w1 - w0,
            "cpu_us_per_step": [1e6 * (b - a) / steps for a, b in zip(c0, c1, strict=True)],
            "load": (load0 + os.getloadavg()[0]) / 2}  # fmt: skip


def run_windseek(binary: Path, seconds: float, tmp: Path) -> dict[str, Any]:
    n = free_instance()
    p = ports(n)
    log = open(tmp / "windseek.log", "wb")  # noqa: SIM115 - closed below
    ws = subprocess.Popen([sys.executable, "-m", "windseek.cli", "sitl", "open-field", "--px4", "--px4-port",
                           str(p["sim"]), "--px4-free"], cwd=REPO, stdout=log, stderr=subprocess.STDOUT)  # fmt: skip
    px4 = Px4Sitl(binary, n, tmp / "px4-hil", tmp / "px4-hil.log", speed=20.0).start()
    try:
        assert px4.proc is not None
        return fly_and_measure(p["api"], seconds, [ws.pid, px4.proc.pid])
    finally:
        ws.send_signal(signal.SIGTERM)
        ws.wait(20)
        px4.stop()
        log.close()


def run_sih(binary: Path, seconds: float, tmp: Path) -> dict[str, Any]:
    n = free_instance()
    timeouts = {k: v for k, v in px4_env(20.0).items() if k.endswith("_LOSS_T")}
    px4 = Px4Sitl(binary, n, tmp / "px4-sih", tmp / "px4-sih.log", sih=True,
                  extra_env={"PX4_SIM_SPEED_FACTOR": "1000", **timeouts}).start()  # fmt: skip
    try:
        assert px4.proc is not None
        return fly_and_measure(ports(n)["api"], seconds, [px4.proc.pid])
    finally:
        px4.stop()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="wall seconds measured in hover (default 30)")
    args = ap.parse_args()
    binary = px4_binary()
    if binary is None:
        print("set WINDSEEK_PX4_BIN to a PX4 SITL binary (build/px4_sitl_*/bin/px4)", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="px4_lockstep_"))
    hil = run_windseek(binary, args.seconds, tmp)
    cw, cp = hil["cpu_us_per_step"]
    print(f"PX4 + windseek (lockstep over TCP): {hil['speed']:.2f}x real time ({hil['sim_s']:.1f} sim s in "
          f"{hil['wall_s']:.1f} s); CPU per 4 ms step: windseek {cw:.0f} us, PX4 {cp:.0f} us (all its threads); "
          f"load {hil['load']:.1f}")  # fmt: skip
    sih = run_sih(binary, args.seconds, tmp)
    (cs,) = sih["cpu_us_per_step"]
    print(f"PX4 SIH (peer, PX4's own physics): {sih['speed']:.2f}x real time; CPU per 4 ms step: PX4 {cs:.0f} us "
          f"(all its threads); load {sih['load']:.1f}")  # fmt: skip
    print(f"windseek-in-the-loop / SIH speed: {hil['speed'] / sih['speed']:.2f}; logs in {tmp}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
