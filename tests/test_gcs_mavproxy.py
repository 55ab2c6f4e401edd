"""Ground stations against the SITL (issue 17): the real MAVProxy (a test dependency) driven through
its command line, as an operator would.

What is checked is what a ground station user meets: the parameter download (MAVProxy asks over
MAVLink FTP first; the SITL answers PX4's NAK at once, so MAVProxy falls back to PARAM_REQUEST_LIST
without waiting out its retries), setting INT32 and REAL32 parameters, arming, ``takeoff 5`` (5 m
AMSL: refused to climb with PX4's STATUSTEXT), a take-off to an AMSL altitude, a mission uploaded
with ``wp load`` and listed with ``wp list``, flown in AUTO.MISSION with its land item reported as
AUTO.MISSION (PX4's way), ``land`` (DO_LAND_START: CANCELLED with a reason without a marker, the
mission's landing with one), RTL. And the README's router recipe from a serial port.

MAVProxy 1.8.75's ``mode NAME`` fails against any PX4 autopilot, real or simulated (pymavlink's
``set_mode_px4`` gets PX4's mode tuple: "required argument is not a float"), so modes are chosen
with ``long DO_SET_MODE 1 MAIN SUB`` and ``long NAV_RETURN_TO_LAUNCH`` here.
"""

from __future__ import annotations

import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from link_support import free_port, running, udp_to, wait_until
from test_link_serial_cli import serial_cable

from sitl.autopilot.flight_modes import Mode
from sitl.link import SerialTransport, SitlLink
from sitl.world.sensors import ned_to_geodetic
from wire.dialect import mavlink as M  # noqa: N812

pytest.importorskip("MAVProxy")

#: Streams MAVProxy does not need and a pure-Python peer would drown in at the test speed.
HIGH_RATE = (M.MAVLINK_MSG_ID_HIL_SENSOR, M.MAVLINK_MSG_ID_HIGHRES_IMU, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
             M.MAVLINK_MSG_ID_ESC_STATUS)  # fmt: skip


class MavProxy:
    """MAVProxy as a subprocess: commands on its stdin, its output lines collected with wall times."""

    def __init__(self, master: str, workdir: Path, *extra: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "MAVProxy.mavproxy", f"--master={master}", f"--state-basedir={workdir}",
             "--nowait", *extra],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=workdir,
            bufsize=1)  # fmt: skip
        self.t0 = time.monotonic()
        self.lines: list[tuple[float, str]] = []
        self._cursor = 0
        self._lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._lock:
                self.lines.append((time.monotonic() - self.t0, line.rstrip()))

    def cmd(self, text: str) -> None:
        assert self.proc.stdin is not None
        with self._lock:
            self._cursor = len(self.lines)  # expect() looks at what comes after the command
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()

    def expect(self, pattern: str, timeout: float) -> re.Match[str]:
        """The first output line from the cursor on matching ``pattern``; fails after ``timeout`` s."""
        rx = re.compile(pattern)
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            with self._lock:
                for i in range(self._cursor, len(self.lines)):
                    m = rx.search(self.lines[i][1])
                    if m:
                        self._cursor = i + 1
                        return m
            time.sleep(0.02)
        raise AssertionError(f"MAVProxy printed no {pattern!r} within {timeout} s:\n" + self.tail())

    def tail(self, n: int = 40) -> str:
        with self._lock:
            return "\n".join(f"{t:6.2f} {s}" for t, s in self.lines[-n:])

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(2)  # MAVProxy's threads often outlive a SIGTERM by 10 s: not what is tested
            except subprocess.TimeoutExpired:
                self.proc.kill()


@pytest.fixture
def sitl_and_mavproxy(tmp_path: Path) -> Iterator[tuple[SitlLink, MavProxy]]:
    port = free_port()
    with running([udp_to(port)]) as link:
        for mid in HIGH_RATE:
            link.streams.set_interval(mid, -1, 0.0)
        wait_until(lambda: link.sim.t > 0.3, 10.0, "the SITL streaming")
        mp = MavProxy(f"udpin:127.0.0.1:{port}", tmp_path)
        try:
            yield link, mp
        finally:
            mp.close()


def _shows(mp: MavProxy, command: str, pattern: str, timeout: float) -> None:
    """Repeat ``command`` until its output matches ``pattern`` (MAVProxy's cache updates asynchronously)."""
    t_end = time.monotonic() + timeout
    while True:
        mp.cmd(command)
        try:
            mp.expect(pattern, 0.5)
            return
        except AssertionError:
            if time.monotonic() > t_end:
                raise


def _wpl(link: SitlLink, path: Path) -> int:
    """A QGC WPL 110 mission (relative altitudes): take-off, waypoint, DO_LAND_START, waypoint, land."""
    home = link.sim.scenario.sensors.home

    def ll(n: float, e: float) -> tuple[float, float]:
        lat, lon, _ = ned_to_geodetic(np.array([n, e, 0.0]), home)
        return lat, lon

    rows = [(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0.0, 0.0, 3.0), (M.MAV_CMD_NAV_WAYPOINT, 0, 0.8, *ll(6.0, 0.0), 3.0),
            (189, 0, 0, 0.0, 0.0, 0.0), (M.MAV_CMD_NAV_WAYPOINT, 0, 0.8, *ll(6.0, 5.0), 3.0),
            (M.MAV_CMD_NAV_LAND, 0, 0, *ll(6.0, 5.0), 0.0)]  # fmt: skip
    lines = ["QGC WPL 110"]
    for seq, (cmd, p1, p2, lat, lon, alt) in enumerate(rows):
        lines.append(f"{seq}\t0\t3\t{cmd}\t{p1}\t{p2}\t0\t0\t{lat:.8f}\t{lon:.8f}\t{alt}\t1")
    path.write_text("\n".join(lines) + "\n")
    return len(rows)


def test_mavproxy_params_takeoff_mission_land_start_rtl(sitl_and_mavproxy: tuple[SitlLink, MavProxy],
                                                        tmp_path: Path) -> None:  # fmt: skip
    link, mp = sitl_and_mavproxy
    sim, fc = link.sim, link.sim.fc
    # Parameters: FTP first (answered at once with PX4's NAK), then the parameter protocol.
    n = len(link.params.params)
    m = mp.expect(rf"Received {n} parameters", 30.0)
    t_detect = next(t for t, s in mp.lines if "Detected vehicle" in s or "online system" in s)
    t_params = next(t for t, s in mp.lines if m.group(0) in s)
    assert link.counters["ftp_naks"] >= 1, "MAVProxy's FTP open was not refused"
    # Unanswered, MAVProxy re-sent its open 11 times over 12-14 s before falling back.
    assert link.counters["ftp_requests"] <= 4, dict(link.counters)
    assert t_params - t_detect < 10.0, mp.tail()
    # INT32 and REAL32 parameters set with their types (MAVProxy decodes PX4's bytewise INT32).
    mp.cmd("param set NAV_DLL_ACT 1")
    wait_until(lambda: link.datalink.action == 1, 5.0, "NAV_DLL_ACT set")
    _shows(mp, "param show NAV_DLL_ACT", r"NAV_DLL_ACT\s+1\b", 10.0)  # the echo reached MAVProxy's cache
    mp.cmd("param set MPC_XY_CRUISE 3.5")
    wait_until(lambda: fc.config.cruise_speed_m_s == pytest.approx(3.5), 5.0, "MPC_XY_CRUISE set")
    assert link.counters["params_type_mismatch"] == 0

    # takeoff 5 = 5 m AMSL, far below home: accepted, no climb, and the reason on the console.
    mp.cmd("arm throttle")
    wait_until(lambda: fc.armed, 10.0, "armed")
    mp.cmd("takeoff 5")
    mp.expect(r"Already higher than takeoff altitude", 10.0)
    mp.expect(r"Takeoff altitude is AMSL: home is 488\.0 m", 10.0)
    assert fc.on_ground and fc.mode == Mode.HOLD
    mp.cmd(f"takeoff {link.home_amsl() + 3.0:.1f}")
    wait_until(lambda: -sim.position[2] > 2.5 and fc.mode == Mode.HOLD, 30.0, "take-off to 3 m")

    # `land` is DO_LAND_START: without a marker in the mission PX4 answers CANCELLED; we say why.
    mp.cmd("land")
    mp.expect(r"result : 6", 10.0)
    mp.expect(r"planned mission landing not available", 10.0)
    # MAVProxy 1.8.75's `mode NAME` fails against any PX4 ("required argument is not a float": pymavlink
    # hands it PX4's mode tuple), so the operator's way is `long`.
    mp.cmd("long NAV_RETURN_TO_LAUNCH")
    wait_until(lambda: fc.mode == Mode.RTL, 10.0, "RTL")
    wait_until(lambda: not fc.armed, 60.0, "RTL landed and disarmed")

    # A mission: wp load, wp list, flown in MISSION mode; `land` jumps to its DO_LAND_START.
    count = _wpl(link, tmp_path / "m.txt")
    mp.cmd(f"wp load {tmp_path / 'm.txt'}")
    mp.expect(rf"Sent all {count} waypoints|Loaded {count} waypoints", 20.0)
    wait_until(lambda: len(fc.mission) == count, 10.0, "mission stored")
    mp.cmd("wp list")
    mp.expect(rf"Requesting {count} waypoints", 10.0)
    mp.expect(r"Saved \d+ waypoints", 20.0)
    mp.cmd("arm throttle")
    wait_until(lambda: fc.armed, 10.0, "armed")
    mp.cmd("long DO_SET_MODE 1 4 4")  # custom mode AUTO.MISSION
    wait_until(lambda: fc.mode == Mode.MISSION and fc.mission_index >= 1, 30.0, "mission flying")
    mp.cmd("land")
    wait_until(lambda: fc.mission_index >= 3, 20.0, "jumped to the DO_LAND_START marker")
    wait_until(lambda: fc.mode == Mode.LAND, 40.0, "landing on the mission's land item")
    # PX4 stays in AUTO.MISSION while it lands on a mission item, and so does the wire.
    assert link.telemetry.reported_mode() == Mode.MISSION
    mp.expect(r"MISSION>", 10.0)
    wait_until(lambda: not fc.armed, 60.0, "landed and disarmed")
    assert link.telemetry.reported_mode() == Mode.MISSION
    assert np.hypot(sim.position[0] - 6.0, sim.position[1] - 5.0) < 1.5
    assert link.counters["handler_errors"] == 0


def test_readme_router_recipe_serial_to_two_udp_outputs(tmp_path: Path) -> None:
    """The README's MAVProxy recipe: one serial port, MAVProxy fanning it out to UDP outputs; both
    outputs get the telemetry, and a command from an output reaches the autopilot."""
    from pymavlink import mavutil

    out_a, out_b = free_port(), free_port()
    # A TELEM2-like 921600 baud link; PX4 would also thin its streams to fit the link (the SITL does not,
    # so the streams nobody needs here are switched off and the pty pipe never backs up).
    with serial_cable() as (dev_sitl, dev_gcs), running([SerialTransport(dev_sitl, 921600)],
                                                        true_wind_hz=0.0) as link:  # fmt: skip
        for mid in (*HIGH_RATE, M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,
                    M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS, M.MAVLINK_MSG_ID_ALTITUDE, M.MAVLINK_MSG_ID_VFR_HUD):
            link.streams.set_interval(mid, -1, 0.0)
        mp = MavProxy(dev_gcs, tmp_path, "--baudrate=921600", f"--out=udp:127.0.0.1:{out_a}",
                      f"--out=udp:127.0.0.1:{out_b}", "--daemon", "--non-interactive")  # fmt: skip
        peers = [mavutil.mavlink_connection(f"udpin:127.0.0.1:{p}", source_system=254 - i, dialect="common")
                 for i, p in enumerate((out_a, out_b))]  # fmt: skip
        try:
            for peer in peers:
                hb = peer.recv_match(type="HEARTBEAT", blocking=True, timeout=20)
                assert hb is not None and hb.autopilot == M.MAV_AUTOPILOT_PX4, mp.tail()
            wait_until(lambda: link.sim.t > 0.3, 10.0, "a GNSS fix")
            while peers[1].recv_match(blocking=False) is not None:
                pass  # read what queued up, so the ACK is not behind a backlog
            peers[1].mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            ack = peers[1].recv_match(type="COMMAND_ACK", blocking=True, timeout=20)
            assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
            assert link.sim.fc.armed
        finally:
            for peer in peers:
                peer.close()
            mp.close()
