"""The windseek entry point: sim --json prints one JSON object with the documented keys; bad arguments
are one-line errors before anything slow happens."""

import json
import os
import subprocess
import sys

import pytest

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


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["sitl", "paper-s1", "--geofence", "1,2,3"], "expected six finite numbers N,E,D,N,E,D, got 3"),
        (["sitl", "paper-s1", "--true-wind-hz", "-1"], "must be a finite rate >= 0 Hz"),
        (["sitl", "paper-s1", "--speed", "0"], "must be > 0"),
    ],
)
def test_bad_sitl_arguments_are_refused_by_the_parser(argv: list[str], says: str, capsys) -> None:
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2 and says in capsys.readouterr().err


def test_bad_values_fail_fast_with_one_line(tmp_path, capsys) -> None:
    """Errors that argparse cannot see are still reported before any link opens or vehicle is waited for."""
    (tmp_path / "binary.toml").write_bytes(b"\x00\xff\xfe")
    (tmp_path / "noname.toml").write_text('description = "no name"\n')
    cases = [
        (["sitl", "paper-s1", "--no-udp", "--serial", "/dev/null:abc"], "baud rate 'abc' is not a number"),
        (["sitl", "paper-s1", "--no-udp", "--serial", "/dev/null:1234"], "baud rate 1234: allowed values"),
        (["mission", "--connect", "udpin://127.0.0.1:9", "--strategy", "surge-cast", "--altitude", "-5"],
         "--altitude -5: the search altitude above home must be in"),
        (["sim", str(tmp_path / "binary.toml")], "binary.toml: not a TOML text file"),
        (["sim", str(tmp_path / "noname.toml")], "name: required"),
    ]  # fmt: skip
    for argv, says in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        # (The altitude is refused before any connection: connecting would end in "no autopilot heartbeat".)
        assert says in err and len(err.splitlines()) == 1, (argv, err)


def test_a_subcommand_imports_only_its_own_module():
    """Every SITL, estimator and proxy process starts through the CLI: it imports the one subcommand
    it runs, not all of them (importing every subcommand cost ~1.3 s of CPU per process), and the
    full help still lists every command."""
    code = ("import sys\nfrom windseek.cli import main\ntry:\n    main(['link-proxy', '--help'])\nexcept SystemExit:\n"
            "    pass\nprint(sorted(m for m in sys.modules if m.startswith('windseek.cmd_') or m == 'scipy'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    assert out.strip().splitlines()[-1] == "['windseek.cmd_link_proxy']", out
    full = subprocess.run([sys.executable, "-m", "windseek.cli", "--help"], capture_output=True, text=True, timeout=60)
    listed = [ln.split()[0] for ln in full.stdout.splitlines() if ln.startswith("    ") and ln[4] != " "]
    assert listed == ["sim", "search", "campaign", "estimate", "identify", "sitl", "mission", "review", "estimator",
                      "demo",
                      "link-proxy"], full.stdout


def test_mission_line_without_a_declaration_says_so() -> None:
    """A mission that declared nothing (time to the declaration NaN) used to print "time nan s"."""
    from mission.result import MissionResult
    from windseek.cmd_mission import result_line

    res = MissionResult(strategy="surge-cast", wind="mavlink", cause="search-ended", path_m=42.0)
    line = result_line(res)
    assert "nan" not in line.lower() and "declared source none (confidence 0.00); time: no declaration;" in line
    res.declared_ned, res.time_s, res.credible_radius_m = [3.0, -4.0, -5.0], 61.25, 2.5
    assert "N 3.0 E -4.0 D -5.0 m, 90 % within 2.5 m (confidence 0.00); time 61.2 s;" in result_line(res)
