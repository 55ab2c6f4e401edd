"""ArduCopter SITL in the tests: the binary from ``WINDSEEK_ARDUPILOT_BIN`` (skip with a reason without it),
a free instance, ``windseek sitl --ardupilot`` and ArduCopter as subprocesses, both stopped at the end, and a
pymavlink ground station for ArduCopter (its mode numbers, its mission protocol)."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from sitl.ardupilot.gcs import COPTER_MODES, CopterGcs  # noqa: F401 - the tests' ground station
from sitl.ardupilot.launch import LISTENING
from sitl.ardupilot.process import ENV_BIN, ArduCopterSitl, ardupilot_binary, copter_defaults, free_instance, ports
from sitl.autopilot_process import stop_process, wait_for_text  # noqa: F401 - the tests' stop
from sitl.scenario import load_scenario

REPO = Path(__file__).resolve().parent.parent


def need_ardupilot() -> Path:
    """The ArduCopter SITL binary, or skip the test saying how to enable it."""
    b = ardupilot_binary()
    if b is None:
        pytest.skip(f"ArduCopter SITL not available: set {ENV_BIN} to a built arducopter (build/sitl/bin/arducopter)")
    if copter_defaults(b) is None:
        pytest.skip("ArduPilot's Tools/autotest/default_params/copter.parm not found: set WINDSEEK_ARDUPILOT_DEFAULTS")
    return b


def home_of(scenario: str) -> str:
    h = load_scenario(scenario).sensors.home
    return f"{h.lat_deg:.7f},{h.lon_deg:.7f},{h.alt_m:g},0"


@dataclass
class ApRun:
    """A running ArduCopter + windseek pair: the instance, its ports, the files of the run."""

    instance: int
    ports: dict[str, int]
    ardupilot: ArduCopterSitl
    windseek: subprocess.Popen[bytes]
    summary_path: Path
    windseek_log: Path

    def summary(self) -> dict[str, Any]:
        return json.loads(self.summary_path.read_text()) if self.summary_path.exists() else {}

    def windseek_text(self) -> str:
        return self.windseek_log.read_text(errors="replace") if self.windseek_log.exists() else ""


@contextlib.contextmanager
def ardupilot_with_windseek(tmp: Path, scenario: str = "calm", speedup: float = 5.0, seed: int | None = None,
                            extra: list[str] | None = None, params: list[Path] | None = None
                            ) -> Iterator[ApRun]:  # fmt: skip
    """``windseek sitl SCENARIO --ardupilot`` and ArduCopter SITL (``--speedup``) on a free instance."""
    binary = need_ardupilot()
    n = free_instance()
    p = ports(n)
    summary, wlog = tmp / "windseek-summary.json", tmp / "windseek.log"
    cmd = [sys.executable, "-m", "windseek.cli", "sitl", scenario, "--ardupilot", "--ardupilot-port", str(p["json"]),
           "--ardupilot-mavlink", f"127.0.0.1:{p['peripheral']}", "--exit-summary", str(summary), *(extra or [])]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    with open(wlog, "wb") as f:
        ws = subprocess.Popen(cmd, cwd=REPO, stdout=f, stderr=subprocess.STDOUT, env=dict(os.environ))
    ap = ArduCopterSitl(binary, n, tmp / "ardupilot", tmp / "ardupilot.log", home_of(scenario), speedup=speedup,
                        params=params)  # fmt: skip
    try:
        # ArduPilot only starts its clock (and its heartbeats) once the physics answers: start it once windseek
        # listens (a cold numba cache can take tens of seconds).
        wait_for_text(wlog, LISTENING, ws)
        ap.start()
        yield ApRun(n, p, ap, ws, summary, wlog)
    finally:
        ap.stop()
        stop_process(ws)
