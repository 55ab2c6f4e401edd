"""PX4 SITL in the tests: the binary from ``WINDSEEK_PX4_BIN`` (skip with a reason without it), a free
instance number, PX4 and ``windseek sitl --px4`` as subprocesses, both stopped at the end."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from sitl.autopilot_process import stop_process
from sitl.hil.px4_process import ENV_BIN, Px4Sitl, free_instance, ports, px4_binary

REPO = Path(__file__).resolve().parent.parent


def need_px4() -> Path:
    """The PX4 SITL binary, or skip the test saying how to enable it."""
    b = px4_binary()
    if b is None:
        pytest.skip(f"PX4 SITL not available: set {ENV_BIN} to a built px4 binary (build/px4_sitl_*/bin/px4)")
    return b


@dataclass
class Px4Run:
    """A running PX4 (+ windseek) pair: the instance, its ports, the files of the run."""

    instance: int
    ports: dict[str, int]
    px4: Px4Sitl
    windseek: subprocess.Popen[bytes] | None
    summary_path: Path
    windseek_log: Path

    def summary(self) -> dict[str, Any]:
        return json.loads(self.summary_path.read_text()) if self.summary_path.exists() else {}

    def windseek_text(self) -> str:
        return self.windseek_log.read_text(errors="replace") if self.windseek_log.exists() else ""


@contextlib.contextmanager
def px4_with_windseek(tmp: Path, scenario: str = "open-field", speed: float = 0.0, px4_speed: float = 10.0,
                      extra: list[str] | None = None, sih: bool = False,
                      px4_env: dict[str, str] | None = None) -> Iterator[Px4Run]:  # fmt: skip
    """``windseek sitl SCENARIO --px4`` (unless ``sih``: PX4's own physics) and PX4 SITL on a free
    instance; ``px4_speed`` scales PX4's link-loss timeouts (the speed lockstep may reach)."""
    binary = need_px4()
    n = free_instance()
    p = ports(n)
    summary = tmp / "windseek-summary.json"
    wlog = tmp / "windseek.log"
    ws = None
    if not sih:
        pace = ["--px4-free"] if speed <= 0 else ["--speed", str(speed)]
        cmd = [sys.executable, "-m", "windseek.cli", "sitl", scenario, "--px4", "--px4-port", str(p["sim"]), *pace,
               "--exit-summary", str(summary), *(extra or [])]  # fmt: skip
        with open(wlog, "wb") as f:
            ws = subprocess.Popen(cmd, cwd=REPO, stdout=f, stderr=subprocess.STDOUT, env=dict(os.environ))
    px4 = Px4Sitl(binary, n, tmp / "px4", tmp / "px4.log", sih=sih, speed=px4_speed, extra_env=px4_env)
    run = Px4Run(n, p, px4, ws, summary, wlog)
    try:
        px4.start()
        yield run
    finally:
        if ws is not None:
            stop_process(ws)
        px4.stop()


def wait_log(run: Px4Run, text: str, timeout_s: float) -> None:
    """Wait until windseek's output contains ``text`` (AssertionError with both logs' tails otherwise)."""
    end = time.monotonic() + timeout_s
    while text not in run.windseek_text():
        if time.monotonic() > end or (run.windseek is not None and run.windseek.poll() is not None):
            raise AssertionError(f"windseek never said {text!r}:\n{run.windseek_text()[-2000:]}\n--- PX4:\n"
                                 f"{run.px4.log_text()[-2000:]}")  # fmt: skip
        time.sleep(0.1)
