"""An autopilot's SITL binary as a subprocess of windseek's tests, benchmarks and scripts: a thin adapter.

:class:`AutopilotProcess` holds what PX4 SITL (:mod:`sitl.hil.px4_process`) and ArduCopter SITL
(:mod:`sitl.ardupilot.process`) share: one process in a fresh working directory, in its own session (so
a signal to the test's process group does not reach it), its output in a log file, stopped with SIGTERM
then SIGKILL after a bounded wait. Subclasses give the command line, environment and ports.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import IO, Any


def stop_process(proc: subprocess.Popen[bytes], timeout_s: float = 20.0) -> int | None:
    """SIGTERM, then SIGKILL after ``timeout_s`` wall seconds; the exit code (None if it never ran)."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.kill(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout_s)
    return proc.returncode


def ports_free(tcp: list[int], udp: list[int]) -> bool:
    """True if every port can be bound on localhost now (TCP ``tcp``, UDP ``udp``)."""
    for kind, ports in ((socket.SOCK_STREAM, tcp), (socket.SOCK_DGRAM, udp)):
        for port in ports:
            with socket.socket(socket.AF_INET, kind) as s:
                try:
                    s.bind(("127.0.0.1", port))
                except OSError:
                    return False
    return True


def wait_for_text(log: Path, text: str, proc: subprocess.Popen[bytes], timeout_s: float = 90.0) -> None:
    """Wait until ``text`` appears in the log file a process writes (e.g. ``windseek sitl``'s "listening"
    line); RuntimeError with the log's tail if the process exits or ``timeout_s`` wall seconds pass."""
    deadline = time.monotonic() + timeout_s
    while text not in (log.read_text(errors="replace") if log.exists() else ""):
        if proc.poll() is not None or time.monotonic() > deadline:
            tail = log.read_text(errors="replace")[-800:] if log.exists() else ""
            raise RuntimeError(f"{text!r} not seen in {log} ({'exited' if proc.poll() is not None else 'timeout'}): "
                               f"{tail}")  # fmt: skip
        time.sleep(0.1)


class AutopilotProcess:
    """One SITL process (see the module docstring): ``args`` and ``env`` are set by the subclass."""

    def __init__(self, workdir: Path, log: Path) -> None:
        self.workdir = Path(workdir)
        self.log_path = Path(log)
        self.args: list[str] = []
        self.env: dict[str, str] | None = None
        self.proc: subprocess.Popen[bytes] | None = None
        self._log: IO[bytes] | None = None

    def prepare(self) -> None:
        """Files the process needs in its working directory, written just before it starts."""

    def start(self) -> Any:
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.prepare()
        self._log = open(self.log_path, "wb")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(self.args, cwd=self.workdir, env=self.env, stdin=subprocess.DEVNULL,
                                     stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True)  # fmt: skip
        return self

    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self, timeout_s: float = 10.0) -> int | None:
        """SIGTERM, then SIGKILL after ``timeout_s``; returns the exit code."""
        code = None if self.proc is None else stop_process(self.proc, timeout_s)
        if self._log is not None:
            self._log.close()
            self._log = None
        return code

    def log_text(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def __enter__(self) -> Any:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()
