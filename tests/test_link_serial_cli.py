"""``windseek sitl`` as a subprocess on a serial link (pseudo-terminals), flown by MAVSDK, and
stopped with SIGINT; plus the UDP defaults and SIGTERM with a pymavlink peer.

Two pseudo-terminal pairs joined by a byte pump stand in for a serial cable: the SITL opens
one slave device, MAVSDK the other, exactly as they would open /dev/ttyUSB0.
"""

from __future__ import annotations

import contextlib
import os
import pty
import select
import signal
import subprocess
import sys
import threading
import time
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest
from link_support import autopilot, first, free_port

pytest.importorskip("mavsdk")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from pymavlink import mavutil  # noqa: E402

pytestmark = pytest.mark.e2e

SCENARIO = """
name = "link-cli"
seed = 3
[wind]
velocity_ned = [0.0, -1.0, 0.0]
[route]
takeoff_altitude_m = 2.0
"""


@contextlib.contextmanager
def serial_cable() -> Iterator[tuple[str, str]]:
    """Two pty slave paths connected to each other through their masters."""
    ends = [pty.openpty() for _ in range(2)]
    for _, slave in ends:
        tty.setraw(slave)  # no echo, no line discipline: a byte pipe like a UART
    stop = threading.Event()
    ma, mb = ends[0][0], ends[1][0]

    def pump() -> None:
        peer = {ma: mb, mb: ma}
        while not stop.is_set():
            ready, _, _ = select.select([ma, mb], [], [], 0.05)
            for fd in ready:
                try:
                    data = os.read(fd, 4096)
                    os.write(peer[fd], data)
                except OSError:
                    pass

    th = threading.Thread(target=pump, daemon=True)
    th.start()
    try:
        yield os.ttyname(ends[0][1]), os.ttyname(ends[1][1])
    finally:
        stop.set()
        th.join(2.0)
        for m, s in ends:
            os.close(m)
            os.close(s)


def _sitl(tmp_path: Path, *args: str) -> subprocess.Popen:
    sc = tmp_path / "link-cli.toml"
    sc.write_text(SCENARIO)
    cmd = [sys.executable, "-m", "windseek.cli", "sitl", str(sc), "--speed", "4", *args]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _stop(proc: subprocess.Popen, sig: int) -> tuple[str, str]:
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return out, err


@pytest.mark.asyncio
async def test_cli_serial_pty_mavsdk_arm_takeoff_and_sigint(tmp_path: Path) -> None:
    with serial_cable() as (dev_sitl, dev_gcs):
        # 25 Hz of HIL_SENSOR: a 115200-baud UART cannot carry the 250 Hz IMU stream (19 kB/s) anyway.
        proc = _sitl(tmp_path, "--no-udp", "--serial", f"{dev_sitl}:115200", "--hil-decimation", "10")
        try:
            async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
                drone = await autopilot(sdk, f"serial://{dev_gcs}:115200", 15.0)
                assert drone is not None, "no autopilot on the serial link"
                tel, action = TelemetryAsync(drone), ActionAsync(drone)
                await first(tel.subscribe_health_all_ok(), bool, 10.0, "health all ok")
                await action.arm()
                await first(tel.subscribe_armed(), bool, 5.0, "armed")
                await action.disarm()
                await first(tel.subscribe_armed(), lambda a: not a, 5.0, "disarmed on the ground")
                await action.arm()
                await action.takeoff()
                pos = await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 1.5, 15.0, "climb")
                assert pos.relative_altitude_m < 3.0
                await action.land()
                await first(tel.subscribe_armed(), lambda a: not a, 20.0, "landed and disarmed")
        finally:
            if proc.poll() is None:
                out, err = _stop(proc, signal.SIGINT)
            else:
                out, err = proc.communicate()
    assert proc.returncode == 0, err
    assert "serial:" + dev_sitl in out
    assert "stopped at t =" in err and "(0 bad)" in err


def test_cli_udp_peers_and_sigterm(tmp_path: Path) -> None:
    port = free_port()
    peer = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=200, dialect="common")
    proc = _sitl(tmp_path, "--udp", f"127.0.0.1:{port}", "--true-wind-hz", "0", "--hil-decimation", "5")
    try:
        hb = peer.recv_match(type="HEARTBEAT", blocking=True, timeout=15)
        assert hb is not None, "no HEARTBEAT on the configured UDP peer"
        assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
        assert hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR and hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
        assert hb.custom_mode == (4 << 16) | (3 << 24)  # AUTO.LOITER on the ground
        assert hb.system_status == mavutil.mavlink.MAV_STATE_STANDBY
        # --true-wind-hz 0: no simulation-only named values on the link; --hil-decimation 5: HIL_SENSOR
        # at 250 / 5 = 50 Hz, the rate of ATTITUDE_QUATERNION.
        n = {"HIL_SENSOR": 0, "ATTITUDE_QUATERNION": 0}
        t_end = time.monotonic() + 1.5
        while time.monotonic() < t_end:
            m = peer.recv_match(blocking=True, timeout=0.2)
            if m is None:
                continue
            assert m.get_type() != "NAMED_VALUE_FLOAT" or not m.name.startswith("TRUEW")
            if m.get_type() in n:
                n[m.get_type()] += 1
        assert n["ATTITUDE_QUATERNION"] > 50
        assert n["HIL_SENSOR"] == pytest.approx(n["ATTITUDE_QUATERNION"], rel=0.15)
    finally:
        out, err = _stop(proc, signal.SIGTERM)
        peer.close()
    assert proc.returncode == 0, err
    assert "stopped at t =" in err
