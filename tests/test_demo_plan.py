"""The demo's plan (``windseek demo``): what it asks of the mission process, checked without
starting one. A demo in a city must fly among the scenario's buildings, as a user would start
``windseek mission --buildings`` (the first paper-s4 demo without it flew into block-2)."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from mission.runners.fence import SiteBuildings
from windseek.cmd_demo import _plan, add_parser, mission_argv, rrd_argv


def _args(tmp_path: Path, *argv: str) -> argparse.Namespace:
    ap = argparse.ArgumentParser()
    add_parser(ap.add_subparsers())
    return ap.parse_args(["demo", "--logs", str(tmp_path), *argv])


@pytest.mark.parametrize(("scenario", "buildings"), [("paper-s4", True), ("open-field", False)])
def test_the_mission_gets_the_buildings_of_an_urban_scenario(tmp_path: Path, scenario: str, buildings: bool) -> None:
    pl = _plan(_args(tmp_path, "--scenario", scenario, "--strategy", "zigzag", "--seed", "7"))
    argv = mission_argv(pl, 14999)
    assert argv[:3] == ["mission", "--connect", "udpin://127.0.0.1:14999"]
    assert argv[argv.index("--seed") + 1] == "7" and argv[argv.index("--strategy") + 1] == "zigzag"
    assert ("--buildings" in argv) is buildings
    # The mission records its side (the posterior, the setpoints) beside the SITL's recording, to be merged.
    assert argv[argv.index("--rrd") + 1] == str(pl.mission_rrd) and pl.mission_rrd.name.endswith(".mission.rrd")
    assert "--rrd" not in mission_argv(_plan(_args(tmp_path, "--no-rrd")), 14999)
    if buildings:  # the argument names a scenario the mission can read its buildings from
        site = SiteBuildings.from_scenario_file(argv[argv.index("--buildings") + 1])
        assert len(site.obstacles.buildings) == 6


def test_the_recorded_geofence_is_the_missions_box_about_the_start(tmp_path: Path) -> None:
    """The mission's box is about home; the SITL draws it in its local frame, where paper-s4 starts
    at (340, 30) m: a box about the origin cut the recording's map away from the whole search."""
    pl = _plan(_args(tmp_path, "--scenario", "paper-s4"))
    n0, e0, d0, n1, e1, d1 = (float(v) for v in pl.fence.split(","))
    assert (n0 + n1) / 2 == pytest.approx(340.0) and (e0 + e1) / 2 == pytest.approx(30.0)
    assert n1 - n0 == pytest.approx(300.0) and d0 < d1 <= 0.0


def test_a_fence_away_from_the_scene_does_not_empty_the_map(tmp_path: Path) -> None:
    from recording.recorder import RunRecorder

    with RunRecorder(tmp_path / "r.rrd", blueprint=False) as rec:
        rec.set_scene([[340.0, 30.0], [428.0, 118.0]])
        inside = rec.scene_bounds()
        rec.geofence((-150.0, -150.0, -30.0), (150.0, 150.0, 0.0))  # about the origin: nowhere near
        assert rec.scene_bounds() == inside
        rec.geofence((190.0, -120.0, -30.0), (400.0, 180.0, 0.0))  # overlapping: the map is cut to it
        n0, n1, e0, e1 = rec.scene_bounds()
        assert n1 == 400.0 and n0 == inside[0] and e0 == inside[2]


@pytest.mark.parametrize(("strategy", "alt"), [("zigzag", "3"), ("infotaxis", "2")])
def test_the_sitl_records_the_urban_wind_slice_at_the_missions_search_altitude(
    tmp_path: Path, strategy: str, alt: str
) -> None:
    """The SITL knows only the scenario's take-off altitude (5 m in paper-s4); the demo tells it the
    mission's search altitude, and the recorded wind field's slice is drawn there."""
    from recording.read import RrdLog
    from recording.sitl_link import LinkRecorder
    from sitl.link.runner import SitlLink
    from sitl.scenario import load_scenario
    from sitl.simulation import Simulation
    from windseek import cmd_sitl

    pl = _plan(_args(tmp_path, "--scenario", "paper-s4", "--strategy", strategy))
    argv = rrd_argv(pl)
    assert argv[argv.index("--rrd-altitude") + 1] == alt
    ap = argparse.ArgumentParser()
    cmd_sitl.add_parser(ap.add_subparsers())
    ns = ap.parse_args(["sitl", "paper-s4", *argv])
    assert ns.rrd_altitude == float(alt)
    with pytest.raises(SystemExit):
        ap.parse_args(["sitl", "paper-s4", "--rrd-altitude", "-1"])  # one line, not a traceback
    path = tmp_path / "s.rrd"
    link = SitlLink(Simulation(load_scenario("paper-s4"), seed=1, autostart_route=False), [])
    LinkRecorder(link, path, strategy=strategy, field_altitude_m=ns.rrd_altitude).close()
    _, labels = RrdLog(path).column("map/wind_field/colorbar/unit", "Points2D:labels")
    assert list(labels[-1]) == [f"m/s at {alt} m"]


URBAN_FILE = Path(__file__).resolve().parent.parent / "mission" / "strategy_files" / "urban.toml"


def test_the_mission_flies_the_strategy_file_given_to_the_demo(tmp_path: Path) -> None:
    """``windseek demo --params FILE`` hands the file to ``windseek mission``, whose own parser and
    loader take it (the urban infotaxis of issue 32 among paper-s4's buildings); without it, none."""
    from mission.strategies.params import InfotaxisParams, load_params
    from windseek import cmd_mission

    pl = _plan(_args(tmp_path, "--scenario", "paper-s4", "--strategy", "infotaxis", "--params", str(URBAN_FILE)))
    argv = mission_argv(pl, 14999)
    assert argv[argv.index("--params") + 1] == str(URBAN_FILE) and "--buildings" in argv
    ap = argparse.ArgumentParser()
    cmd_mission.add_parser(ap.add_subparsers())
    ns = ap.parse_args(argv)
    assert ns.params == str(URBAN_FILE) and ns.strategy == "infotaxis"
    params = load_params(ns.strategy, ns.params)
    assert isinstance(params, InfotaxisParams) and params.plume_model == "urban"
    assert "--params" not in mission_argv(_plan(_args(tmp_path, "--strategy", "infotaxis")), 14999)


def test_the_strategy_files_altitude_is_the_recorded_search_altitude(tmp_path: Path) -> None:
    f = tmp_path / "high.toml"
    f.write_text("[strategy]\naltitude_m = 6.0\n")
    pl = _plan(_args(tmp_path, "--scenario", "paper-s4", "--strategy", "zigzag", "--params", str(f)))
    assert pl.search_altitude_m == 6.0 and rrd_argv(pl)[rrd_argv(pl).index("--rrd-altitude") + 1] == "6"


@pytest.mark.parametrize(("text", "said"), [(None, "does not exist"), ("[strategy]\nspeed_m_s = 99\n", "speed_m_s"),
                                            ("[strategy.infotaxis]\nplume_model = 'city'\n", "plume_model")])
def test_a_bad_strategy_file_is_one_line_before_anything_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str | None, said: str
) -> None:
    from windseek.cli import main

    f = tmp_path / "bad.toml"
    if text is not None:
        f.write_text(text)
    logs = tmp_path / "logs"
    rc = main(["demo", "--logs", str(logs), "--strategy", "infotaxis", "--params", str(f), "--wall-limit", "5"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("windseek demo: error: ") and said in err[0], err
    assert not logs.exists()  # nothing started, no log folder


def test_found_is_the_strategys_success_radius(tmp_path: Path) -> None:
    """Infotaxis states its confidence for 3 m and the search tables count it found within 3 m; the
    demo did so within 5 m for every strategy (a 4 m declaration was "found")."""
    from windseek.cmd_demo import make_summary

    mission = {"cause": "declared", "declared_ned": [4.0, 0.0, -2.0], "confidence": 0.95}
    truth = {"true_sources_ned_m": [[0.0, 0.0, -1.0]]}
    for strategy, found in (("infotaxis", False), ("surge-cast", True)):
        s = make_summary("open-field", strategy, 1, 3.0, mission, truth, 1.0, {})
        assert s["found"] is found and s["declared_error_horizontal_m"] == 4.0, s["reason"]
        assert s["success_radius_m"] == (3.0 if strategy == "infotaxis" else 5.0)
