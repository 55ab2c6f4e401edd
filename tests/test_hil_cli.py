"""``windseek sitl SCENARIO --px4`` as a command: a pymavlink stand-in for PX4 connects to the process,
SIGTERM stops it with the exit summary and the .tlog written; options that do not apply are refused
with one line."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from hil_support import FakePx4, wait_for
from link_support import free_port

from wire.dialect import mavlink

REPO = Path(__file__).resolve().parent.parent


def test_px4_mode_serves_a_px4_and_writes_its_summary_and_tlog(tmp_path: Path) -> None:
    port = free_port(socket.SOCK_STREAM)
    summary, tlog = tmp_path / "s.json", tmp_path / "run.tlog"
    proc = subprocess.Popen([sys.executable, "-m", "windseek.cli", "sitl", "paper-s1", "--px4", "--px4-port",
                             str(port), "--px4-free", "--px4-mavlink", "none", "--exit-summary", str(summary),
                             "--tlog", str(tlog)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip
    try:
        end = time.monotonic() + 300.0  # a cold numba cache compiles the kernels first
        px4 = None
        while px4 is None:
            try:
                px4 = FakePx4(port, sysid=9)
            except OSError:
                assert time.monotonic() < end and proc.poll() is None, "windseek never listened"
                time.sleep(0.2)
        wait_for(lambda: len(px4.seen.sensor_us) > 500, 300.0, "500 lockstep steps")
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
        px4.close()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "as PX4's simulator on tcp:127.0.0.1" in out
    assert "paper-s1 starts airborne at 10 m; with PX4 flying it starts on the ground" in err
    assert "PX4 in lockstep" in err and "stopped at t = " in err
    s = json.loads(summary.read_text())
    assert s["sync"] == "lockstep" and s["px4_system_id"] == 9 and s["answers"] >= 500
    assert s["on_ground"] and not s["crashed"] and s["lockstep_timeouts"] == 0
    # The .tlog: 8-byte time stamps and frames, both directions of the simulator link.
    parser = mavlink.MAVLink(None, 0, 0)
    parser.robust_parsing = True
    data = tlog.read_bytes()
    kinds: dict[str, int] = {}
    i = 0
    while i + 8 < len(data):
        i += 8
        length = data[i + 1] + (12 if data[i] == 0xFD else 8)
        for m in parser.parse_buffer(data[i:i + length]) or []:
            kinds[m.get_type()] = kinds.get(m.get_type(), 0) + 1
        i += length
    assert kinds.get("HIL_SENSOR", 0) >= 500 and kinds.get("HIL_ACTUATOR_CONTROLS", 0) >= 500
    assert kinds.get("HIL_GPS", 0) > 0


def test_options_of_windseeks_own_autopilot_are_refused_with_px4() -> None:
    r = subprocess.run([sys.executable, "-m", "windseek.cli", "sitl", "open-field", "--px4", "--tcp", "5760"],
                       cwd=REPO, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines[-1].startswith("windseek sitl: error: --tcp: not with --px4 (PX4 is the autopilot")
    assert "Traceback" not in r.stderr
