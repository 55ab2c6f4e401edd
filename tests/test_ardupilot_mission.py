"""The estimator and the MAVSDK mission runner against ArduCopter SITL flying windseek's world: a real ArduCopter
built from source (``WINDSEEK_ARDUPILOT_BIN``; skipped without it). ``windseek estimator`` on SERIAL0 and
``windseek mission --strategy surge-cast --wind estimated`` on SERIAL1, as ``benchmarks/ardupilot_search.py``
runs them per seed; windseek records the run (``--rrd``): ArduCopter EKF3's wind beside the UKF's and the truth."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from ardupilot_support import REPO, ardupilot_with_windseek, stop_process

from recording.read import RrdLog

pytestmark = [pytest.mark.e2e, pytest.mark.ardupilot]
SPEEDUP = 5.0


def test_surge_cast_through_arducopter_finds_the_source_with_the_estimator_beside(tmp_path: Path) -> None:
    rrd = tmp_path / "run.rrd"
    with ardupilot_with_windseek(tmp_path, "open-field-low", speedup=SPEEDUP, seed=7,
                                 extra=["--rrd", str(rrd), "--rrd-strategy", "surge-cast"]) as run:
        est_log = open(tmp_path / "estimator.log", "wb")  # noqa: SIM115 - closed below
        est = subprocess.Popen([sys.executable, "-m", "windseek.cli", "estimator", "--connect",
                                f"tcpout://127.0.0.1:{run.ports['gcs']}", "--esc-component", "158", "--json",
                                "--link-timeout", "60", "--connect-timeout", "60"],
                               cwd=REPO, stdout=subprocess.PIPE, stderr=est_log)  # fmt: skip
        try:
            m = subprocess.run([sys.executable, "-m", "windseek.cli", "mission", "--connect",
                                f"tcpout://127.0.0.1:{run.ports['companion']}", "--strategy", "surge-cast", "--wind",
                                "estimated", "--esc-component", "158", "--seed", "7", "--speed-hint", f"{SPEEDUP:g}",
                                "--json"], cwd=REPO, capture_output=True, text=True, timeout=400)  # fmt: skip
        finally:
            stop_process(est)  # type: ignore[arg-type]
            est_log.close()
        est_out = est.stdout.read().decode() if est.stdout else ""  # type: ignore[union-attr]
    log = m.stderr
    assert m.returncode == 0, log[-3000:]
    res = json.loads(m.stdout.strip().splitlines()[-1])
    s = run.summary()
    # The mission on ArduCopter: its failsafe checked, GUIDED as offboard, found, landed over it.
    assert "FS_GCS_ENABLE = 1" in log and "MAV_GCS_SYSID = 245" in log, log[-3000:]
    assert "GUIDED (OFFBOARD)" in log and "LAND (AUTO.LAND)" in log, log[-3000:]
    assert res["cause"] == "declared" and res["landed"] and res["disarmed"], res
    assert "ESC_TELEMETRY_1_TO_4" in res["wind_source"], res["wind_source"]
    assert s["declared_error_horizontal_m"] is not None and s["declared_error_horizontal_m"] < 5.0, s
    assert not s["crashed"] and s["on_ground"], s
    # The estimator beside it on ArduPilot's streams, its WIND_COV routed back by ArduPilot and scored.
    e = json.loads(est_out.strip().splitlines()[-1])
    assert e["inputs"] == {"attitude": "ATTITUDE_QUATERNION", "velocity": "LOCAL_POSITION_NED",
                           "rotors": "ESC_TELEMETRY_1_TO_4"}, e["inputs_line"]  # fmt: skip
    assert s["wind_estimates_scored"] > 100, s
    rmse = s["wind_rmse_ned_m_s"]
    assert math.hypot(rmse[0], rmse[1]) < 1.0 and rmse[2] < 0.6, rmse
    _check_recording(RrdLog(rrd), s)


def _check_recording(log: RrdLog, s: dict) -> None:
    """The recording of that flight: truth, windseek's UKF and ArduCopter EKF3's own wind on the same plots, scored
    as the exit summary scored them."""
    t_truth, truth = log.scalars("wind/east/truth")
    t_est, est = log.scalars("wind/east/estimate")
    t_ap, ap = log.scalars("wind/east/autopilot")
    assert len(t_truth) > 100 and len(t_est) > 100 and len(t_ap) > 100, (len(t_truth), len(t_est), len(t_ap))
    assert log.column("wind/east/autopilot", "SeriesLines:names")[1][-1] in ("ArduCopter EKF3 E", ["ArduCopter EKF3 E"])
    for e in ("wind/speed/autopilot", "wind/direction/autopilot", "wind/east/band", "world/vehicle", "chem/value"):
        assert e in log.entity_paths() + log.series(), e
    # ArduCopter's estimate as the exit summary scored it: the same messages, the same last one.
    last = [log.scalars(f"wind/{a}/autopilot")[1][-1] for a in ("north", "east", "down")]
    assert np.allclose(last, s["autopilot_wind"]["last_estimate_ned_m_s"], atol=1e-3), last
    assert s["autopilot_wind"]["scored"] > 100 and np.all(np.isfinite(est)) and np.all(np.isfinite(truth))
    rs = log.summary()
    assert rs is not None and rs.declared_ned is not None and rs.wind_scored == s["wind_estimates_scored"], rs
    assert "ArduCopter EKF3 wind vs truth" in rs.extra and "not scored" not in rs.extra["ArduCopter EKF3 wind vs truth"]
    assert "GUIDED" in [m for _, m in log.states("phases/mode")]
