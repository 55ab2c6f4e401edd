"""``windseek estimator`` over a real UDP socket: a second system on the link and an autopilot reboot.

A pymavlink sender plays the autopilot (system 1) from a simulated flight, paced at 5x real time,
with another system (7, its clock 500 s ahead) interleaved; after 12 s the autopilot reboots (its
clock starts again near 0). The estimator (a subprocess) must lock on to system 1, say once that
system 7 is there, restart at the reboot and go on publishing WIND_COV on the new clock.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

from estimator_stream import autopilot_messages, record
from link_support import free_port

from wire.dialect import mavlink

ROOT = Path(__file__).resolve().parent.parent
SPEED = 5.0  # simulated seconds per wall second


def test_estimator_locks_on_and_restarts_after_a_reboot_over_udp() -> None:
    f = record(20.0)
    other = record(20.0, scenario="paper-s2", seed=5)
    before = [(t, 1, m) for t, m in autopilot_messages(f) if t < 12.0]
    after = [(t, 1, m) for t, m in autopilot_messages(f, t_offset=-11.5) if t >= 12.0]
    seven = [(t, 7, m) for t, m in autopilot_messages(other, t_offset=500.0) if t < 20.0 and int(t * 250) % 5 == 0]
    plan = sorted(before + after + seven, key=lambda x: x[0])
    port = free_port()
    est = subprocess.Popen(
        [sys.executable, "-m", "windseek.cli", "estimator", "--connect", f"udpin://127.0.0.1:{port}",
         "--json", "--progress-every", "0", "--link-timeout", "5", "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(est.stderr.readline, "")), daemon=True)
    reader.start()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    tx = {s: mavlink.MAVLink(None, srcSystem=s, srcComponent=1) for s in (1, 7)}
    rx = mavlink.MAVLink(None)
    got = []

    def drain() -> None:
        while True:
            try:
                data = sock.recv(65536)
            except BlockingIOError:
                return
            got.extend(rx.parse_buffer(data) or [])

    try:
        end = time.monotonic() + 120.0  # it imports and loads its compiled kernels first
        while not any("connecting on" in x for x in lines) and est.poll() is None and time.monotonic() < end:
            time.sleep(0.05)
        assert any("connecting on" in x for x in lines), lines
        wall0 = time.monotonic()
        for t, sysid, m in plan:
            while time.monotonic() - wall0 < t / SPEED:
                drain()
                time.sleep(0.002)
            sock.sendto(m.pack(tx[sysid]), ("127.0.0.1", port))
        time.sleep(1.0)
        drain()
    finally:
        est.send_signal(signal.SIGTERM)
        out = est.stdout.read() if est.wait(timeout=30) is not None else ""
        reader.join(5.0)
        err = "".join(lines)
        sock.close()
    assert est.returncode == 0, err
    s = json.loads(out)
    assert s["autopilot"] == "1:1" and s["stop_reason"] == "SIGTERM"
    assert s["counters"]["other_system"] > 1000 and s["counters"]["clock_resets"] == 1 and s["restarts"] == 1
    assert err.count("another MAVLink system on the link: 7:1") == 1, err
    assert "autopilot clock reset" in err and "inputs: IMU HIL_SENSOR 250 Hz" in err
    assert not any("out_of_order" in k for k in s["rejected"]), s["rejected"]
    wc = [m for m in got if m.get_type() == "WIND_COV"]
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in wc} == {(1, 191)}
    t = [m.time_usec * 1e-6 for m in wc]
    k = next(i for i in range(1, len(t)) if t[i] < t[i - 1])  # the first WIND_COV after the reboot
    assert t[k - 1] > 11.0 and t[k] < 3.0 and len(t) - k > 40 and t[-1] > 8.0
    assert all(x < 100.0 for x in t)  # never on system 7's clock
    assert len(wc) <= s["wind_cov_published"]  # (any sent after the last read are not in got)
