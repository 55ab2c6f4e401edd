"""The demo's moving parts: child processes with their logs, and a passive MAVLink observer.

:class:`Proc` runs one ``windseek`` subcommand with its output in a log file (and a tail for error
messages); :class:`Observer` listens on a UDP port without sending heartbeats (so it never counts as
a ground station) and keeps the vehicle's mode, arming, position, chemical reading and wind
estimate for the progress line. Every wait is bounded.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, TextIO

import numpy as np


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
        assert stream is not None  # both pipes are opened in __init__
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


#: The observer's MAVLink system id for its PARAM_SETs (not 250, pymavlink's default, nor MAVSDK's 245).
OBSERVER_SYSTEM = 251


class Observer(threading.Thread):
    """A UDP peer of the SITL that follows the vehicle for the progress display. It sends no HEARTBEAT
    (it must not count as a data link), only the PARAM_SETs of :meth:`set_param`."""

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
        self.params: dict[str, float] = {}
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
        elif mtype == "PARAM_VALUE":
            self.params[str(m.param_id).rstrip("\x00")] = float(m.param_value)

    def set_param(self, name: str, value: float, timeout_s: float = 10.0) -> bool:
        """PARAM_SET (REAL32) to the SITL until its PARAM_VALUE echoes ``value``; False after
        ``timeout_s`` wall seconds (or before the SITL was heard from)."""
        end = time.monotonic() + timeout_s
        enc = self.mav.MAVLink(None, OBSERVER_SYSTEM, 1)
        frame = enc.param_set_encode(1, 1, name.encode(), value, self.mav.MAV_PARAM_TYPE_REAL32).pack(enc)
        while time.monotonic() < end:
            got = self.params.get(name)
            if got is not None and abs(got - value) <= 1e-6 * max(1.0, abs(value)):
                return True
            if self.sitl_addr is not None:
                self.sock.sendto(frame, self.sitl_addr)
            time.sleep(0.2)
        return False

    def status(self) -> str:
        from recording.sim_hook import wind_speed_from_deg

        n, e, d = self.pos
        s = f"t {self.t:6.1f} s  {self.mode or '-':12s} N {n:+6.1f} E {e:+6.1f} alt {-d:4.1f} m  chem {self.chem:6.2f}"
        if self.wind is not None:
            sp, fr = wind_speed_from_deg(np.asarray(self.wind, dtype=float))
            s += f"  wind est {sp:4.1f} m/s from {fr:3.0f} deg"
        return s

    def close(self) -> None:
        self._halt.set()
        self.join(timeout=2.0)
        self.sock.close()


