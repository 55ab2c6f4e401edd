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
import subprocess
from pathlib import Path
from typing import IO, Any


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
        p = self.proc
        if p is not None and p.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(p.pid, signal.SIGTERM)
            try:
                p.wait(timeout_s)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(p.pid, signal.SIGKILL)
                p.wait(timeout_s)
        if self._log is not None:
            self._log.close()
            self._log = None
        return None if p is None else p.returncode

    def log_text(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def __enter__(self) -> Any:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()
