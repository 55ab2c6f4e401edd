"""The windseek entry point: sim --json prints one JSON object with the documented keys."""

import json
import os
import subprocess
import sys

from windseek.cli import main


def test_sim_json(capsys):
    assert main(["sim", "paper-s1", "--duration", "3", "--seed", "5", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("sim_time_s", "wall_time_s", "realtime_factor", "position_error_rms_m", "max_tilt_deg", "crashed"):
        assert key in out
    assert out["sim_time_s"] == 3.0 and out["seed"] == 5 and out["crashed"] is False
    assert out["realtime_factor"] > 1.0


def test_sim_text_and_bad_scenario(capsys):
    assert main(["sim", "paper-s2", "--duration", "2", "--no-progress"]) == 0
    assert "position error RMS" in capsys.readouterr().out
    assert main(["sim", "nope"]) == 2
    err = capsys.readouterr().err
    assert "unknown scenario" in err and "Traceback" not in err


def test_installed_entry_point():
    exe = os.path.join(os.path.dirname(sys.executable), "windseek")
    cmd = [exe, "sim", "paper-s1", "--duration", "1", "--json"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["sim_time_s"] == 1.0
