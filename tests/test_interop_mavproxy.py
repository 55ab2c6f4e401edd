"""The README's "one link, several programs" recipe with the real MAVProxy as the router.

``windseek sitl`` streams to MAVProxy's master port only (as an autopilot on a serial port
would); MAVProxy fans it out to UDP outputs; ``windseek mission`` (MAVSDK) flies the search on
one output with the estimator inside (``--wind estimated``), through MAVProxy both ways (its
commands and offboard setpoints go to the master). MAVProxy does not forward between its
outputs, which is why the README runs the estimator inside the mission behind MAVProxy and a
separate ``windseek estimator`` only behind mavlink-router.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from link_support import free_port
from pymavlink import mavutil

pytestmark = pytest.mark.e2e

ROOT = Path(__file__).resolve().parents[1]


def _set_param_through(port: int, name: str, value: float, timeout_s: float = 20.0) -> None:
    """PARAM_SET (REAL32) from a pymavlink ground station on MAVProxy's output ``port`` until the
    autopilot's PARAM_VALUE echoes ``value``."""
    os.environ["MAVLINK20"] = "1"
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
    try:
        end = time.monotonic() + timeout_s
        assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=timeout_s) is not None, "no heartbeat"
        while time.monotonic() < end:
            conn.mav.param_set_send(1, 1, name.encode(), value, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
            m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1.0)
            if m is not None and m.param_id == name and abs(m.param_value - value) < 1e-6:
                return
        raise AssertionError(f"{name} = {value:g} not echoed through MAVProxy within {timeout_s:g} s")
    finally:
        conn.close()


def test_search_mission_through_mavproxy(tmp_path: Path) -> None:
    master, out_mission, out_gcs = free_port(), free_port(), free_port()
    sitl = subprocess.Popen(
        [sys.executable, "-m", "windseek.cli", "sitl", "open-field-low", "--speed", "3", "--udp-bind", "127.0.0.1:0",
         "--udp", f"127.0.0.1:{master}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
    proxy = subprocess.Popen(
        [sys.executable, "-m", "MAVProxy.mavproxy", f"--master=udpin:127.0.0.1:{master}",
         f"--out=udp:127.0.0.1:{out_mission}", f"--out=udp:127.0.0.1:{out_gcs}", "--daemon", "--non-interactive",
         f"--state-basedir={tmp_path}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=tmp_path)  # fmt: skip
    try:
        # PX4's offboard-loss timeout counts vehicle time: 1 s is 0.33 s of wall clock at --speed 3, less
        # than MAVProxy's relaying stalls on a loaded machine (the vehicle then leaves offboard and the
        # mission aborts "offboard-lost"). 1 s of wall clock, as `windseek demo` sets it; through MAVProxy.
        _set_param_through(out_gcs, "COM_OF_LOSS_T", 3.0)
        res = subprocess.run(
            [sys.executable, "-m", "windseek.cli", "mission", "--connect", f"udpin://127.0.0.1:{out_mission}",
             "--strategy", "surge-cast", "--wind", "estimated", "--speed-hint", "3", "--time-limit", "200", "--json"],
            capture_output=True, text=True, timeout=150, cwd=ROOT)  # fmt: skip
    finally:
        for p in (proxy, sitl):
            p.send_signal(signal.SIGTERM)
        proxy_out = proxy.communicate(timeout=20)[0]
        sitl.communicate(timeout=20)
    assert res.returncode in (0, 1), f"{res.stderr[-3000:]}\nMAVProxy: {proxy_out[-2000:]}"
    s = json.loads(res.stdout.strip().splitlines()[-1])
    # The whole protocol went through MAVProxy: arm, take-off, offboard, land, disarm.
    why = {k: s.get(k) for k in ("cause", "reason", "mission_time_s", "setpoint_rate_hz", "tick_rate_hz")}
    assert s["cause"] == "declared" and s["landed"] and s["disarmed"], (why, res.stderr[-3000:], s)
    # One setpoint per strategy tick at 10 Hz of vehicle time; a tick whose moment telemetry skipped over
    # (MAVProxy relays in bursts on a loaded machine) is counted, never queued.
    assert s["setpoint_rate_hz"] >= 8.0, s
    # The live UKF ran on the telemetry MAVProxy relayed (250 Hz HIL_SENSOR, ESC_STATUS, ...).
    est = s["estimator"]
    handled = est["accepted"]["imu"] + est.get("imu_decimated", 0) + est.get("dropped", 0)
    # (150 of 250 Hz: a UDP relay on a loaded machine loses some datagrams before they reach the runner.)
    assert est["imu_message"] == "HIL_SENSOR" and handled > 150 * est["span_s"], est
    assert est["accepted"]["rotors"] > 0 and est["accepted"]["gnss"] > 0
    # Its last estimate is the one from before the landing (the filter pauses at MAV_LANDED_STATE
    # LANDING): 5 m/s from the north, no touchdown "updraft".
    wn, we, wd = s["wind_ned"]
    assert math.hypot(wn + 5.0, we) < 2.0 and abs(wd) < 1.5, s["wind_ned"]  # was [0.3, 0.0, -7.4]
