"""Campaign files -> missions: the grid, the parameters set through the scenario and strategy parsers,
stable keys, and one clear error naming the field for every mistake (before anything runs)."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from mission.campaign.grid import expand
from mission.campaign.scenario_params import apply
from mission.campaign.spec import CampaignError, load_campaign
from sitl.scenario import parse_scenario, scenario_table

ROOT = Path(__file__).resolve().parent.parent


def _spec(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


BASE = """
[campaign]
name = "t"
scenarios = ["open-field"]
strategies = ["surge-cast", "zigzag"]
winds = ["estimated", "oracle"]
seeds = { start = 1000, count = 3 }
"""


def test_grid_is_the_product_and_keys_are_stable(tmp_path: Path) -> None:
    p = _spec(tmp_path, BASE + '[campaign.scenario]\nwind_speed_m_s = [3, 5]\n')
    tasks = expand(load_campaign(p))
    assert len(tasks) == 2 * 2 * 3 * 2  # strategies x winds x seeds x speeds
    assert len({t.key for t in tasks}) == len(tasks)
    again = expand(load_campaign(p))
    assert [t.key for t in again] == [t.key for t in tasks]
    # a parameter value changes the key; so does the seed
    speeds = {t.params["wind_speed_m_s"] for t in tasks}
    assert speeds == {3, 5}
    t3 = next(t for t in tasks if t.params["wind_speed_m_s"] == 3)
    assert t3.scenario_table["wind"]["speed_m_s"] == 3
    assert parse_scenario(t3.scenario_table, "x").wind.velocity_ned[0] == pytest.approx(-3.0)


def test_adding_a_value_keeps_the_keys_of_the_others(tmp_path: Path) -> None:
    a = {t.key for t in expand(load_campaign(_spec(tmp_path, BASE + '[campaign.scenario]\nwind_speed_m_s = [3]\n')))}
    b = {t.key for t in expand(load_campaign(_spec(tmp_path, BASE + '[campaign.scenario]\nwind_speed_m_s = [3, 4]\n',
                                                   "d.toml")))}  # fmt: skip
    assert a < b and len(b) == 2 * len(a)


def test_ranges_and_seed_lists(tmp_path: Path) -> None:
    p = _spec(tmp_path, """
        [campaign]
        name = "r"
        scenarios = ["open-field"]
        strategies = ["surge-cast"]
        seeds = [5, 9]
        [campaign.scenario]
        turbulence_intensity = { start = 0.1, stop = 0.3, step = 0.1 }
        [campaign.strategy]
        "surge-cast.cast_half_width_m" = { start = 2, stop = 6, num = 3 }
    """)
    tasks = expand(load_campaign(p))
    assert sorted({t.params["turbulence_intensity"] for t in tasks}) == [0.1, 0.2, 0.3]
    assert sorted({t.params["surge-cast.cast_half_width_m"] for t in tasks}) == [2.0, 4.0, 6.0]
    assert {t.seed for t in tasks} == {5, 9}
    assert {t.wind for t in tasks} == {"estimated"}
    assert len(tasks) == 3 * 3 * 2
    t = tasks[0]
    # intensity replaces the base scenario's turbulence level (the parser accepts exactly one)
    assert "level" not in t.scenario_table["turbulence"]
    assert t.strategy_table == {"surge-cast": {"cast_half_width_m": t.params["surge-cast.cast_half_width_m"]}}


def test_a_knob_of_one_strategy_does_not_multiply_the_others(tmp_path: Path) -> None:
    knobs = '[campaign.strategy]\n"surge-cast.cast_half_width_m" = [2, 4, 6]\naltitude_m = [2.5, 3]\n'
    p = _spec(tmp_path, BASE + knobs)
    tasks = expand(load_campaign(p))
    surge = [t for t in tasks if t.strategy == "surge-cast"]
    zig = [t for t in tasks if t.strategy == "zigzag"]
    assert len(surge) == 3 * 2 * 2 * 3 and len(zig) == 2 * 2 * 3
    assert all("surge-cast.cast_half_width_m" not in t.params for t in zig)


def test_start_distance_moves_the_source_upwind() -> None:
    base = scenario_table("open-field")[0]
    base["wind"] = {"velocity_ned": [0.0, -4.0, 0.0]}  # air moving west: a wind from the east
    t = apply(base, {"start_distance_m": 80.0})
    sc = parse_scenario(t, "x")
    n, e, d = sc.plume.plume.sources[0].position_ned  # type: ignore[union-attr]
    assert (n, e, d) == pytest.approx((0.0, 80.0, -2.0), abs=1e-6)
    assert t["wind"]["from_deg"] == pytest.approx(90.0) and t["wind"]["speed_m_s"] == pytest.approx(4.0)
    assert sc.wind.velocity_ned == pytest.approx((0.0, -4.0, 0.0), abs=1e-9)


def test_dotted_paths_reach_nested_tables() -> None:
    base = scenario_table("open-field")[0]
    t = apply(base, {"sensor_threshold_mg_m3": 0.2, "plume.sources[0].rate_g_s": 2.0, "stability": "F"})
    sc = parse_scenario(t, "x")
    assert sc.plume is not None
    assert sc.plume.sensor.detection_limit_mg_m3 == 0.2
    assert sc.plume.plume.sources[0].rate_g_s == 2.0 and sc.plume.plume.stability == "F"
    assert base["plume"]["sensor"]["detection_limit_mg_m3"] == 0.05  # the base table is not touched


@pytest.mark.parametrize(("extra", "message"), [
    ('[campaign.scenario]\nwindspeed = [3, 5]\n', "unknown scenario parameter 'windspeed'"),
    ('[campaign.scenario]\n"wind.sped_m_s" = [3, 5]\n', "unknown key(s) sped_m_s"),
    ('[campaign.scenario]\nwind_speed_m_s = [3, -5]\n', "wind.speed_m_s = -5: allowed range is [0.0, 100.0]"),
    ('[campaign.scenario]\nstability = ["D", "Q"]\n', "plume.stability = 'Q'"),
    ('[campaign.scenario]\nwind_speed_m_s = []\n', "wind_speed_m_s is empty: nothing to run"),
    ('[campaign.scenario]\nwind_speed_m_s = [3, "fast"]\n', "mixes types"),
    ('[campaign.strategy]\naltitud_m = [2, 3]\n', "strategy.altitud_m: unknown common parameter"),
    ('[campaign.strategy]\n"surge-cast.lost_s" = [0.01]\n', "strategy.surge-cast.lost_s = 0.01: allowed range"),
    ('[campaign.strategy]\n"anemotaxis.lost_s" = [2]\n', "which this grid does not fly"),
    ('[campaign.scenario]\nturbulence_intensity = { start = 0.1, stop = 0.3 }\n', "a range is"),
])  # fmt: skip
def test_bad_values_name_the_field(tmp_path: Path, extra: str, message: str) -> None:
    with pytest.raises(CampaignError) as e:
        expand(load_campaign(_spec(tmp_path, BASE + extra)))
    assert message in str(e.value)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(("text", "message"), [
    (BASE.replace('seeds = { start = 1000, count = 3 }', 'seeds = []'), "seeds is empty: nothing to run"),
    (BASE.replace('seeds = { start = 1000, count = 3 }', 'seeds = { start = 1000, count = 0 }'), "count = 0"),
    (BASE.replace('"zigzag"', '"zig"'), "'zig' is not one of"),
    (BASE.replace('"oracle"', '"mavlink"'), "'mavlink' is not one of"),
    (BASE.replace('strategies = ["surge-cast", "zigzag"]', 'strategies = []'), "strategies is empty"),
    (BASE.replace('["open-field"]', '["paper-s1"]'), "has no [plume] table"),
    (BASE.replace('["open-field"]', '["no-such"]'), "unknown scenario 'no-such'"),
    (BASE + "bogus = 1\n", "[campaign]: unknown key(s) bogus"),
    (BASE.replace('name = "t"', ''), "campaign.name"),
    ("[campaign\n", "TOML syntax error"),
])  # fmt: skip
def test_bad_campaign_files(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(CampaignError) as e:
        expand(load_campaign(_spec(tmp_path, text)))
    assert message in str(e.value)


def test_grids_inherit_the_campaign_and_merge_duplicates(tmp_path: Path) -> None:
    p = _spec(tmp_path, BASE + """
        [[grid]]
        [[grid]]
        scenarios = ["open-field", "open-field-high"]
        strategies = ["surge-cast"]
        seeds = [1000]
    """)
    spec = load_campaign(p)
    assert len(spec.grids) == 2 and spec.grids[0].strategies == ("surge-cast", "zigzag")
    tasks = expand(spec)
    # grid 1's open-field missions are grid 0's (same keys): flown once
    assert len(tasks) == 2 * 2 * 3 + 1 * 2 * 1
    assert {t.scenario for t in tasks} == {"open-field", "open-field-high"}


def test_repository_campaign_files_expand() -> None:
    files = sorted((ROOT / "campaigns").glob("*.toml"))
    assert files, "campaigns/*.toml"
    for f in files:
        tasks = expand(load_campaign(f))
        assert tasks and all(math.isfinite(t.seed) for t in tasks), f


def test_cli_dry_run_and_bad_input_are_one_line(tmp_path: Path) -> None:
    good = _spec(tmp_path, BASE)
    out = tmp_path / "res"
    r = subprocess.run([sys.executable, "-m", "windseek.cli", "campaign", str(good), "--dry-run", "--out", str(out)],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "12 missions, 0 already finished" in r.stderr and "12 to fly" in r.stderr
    assert not out.exists()  # a dry run writes nothing
    bad = _spec(tmp_path, BASE + '[campaign.scenario]\nwindspeed = [3]\n', "bad.toml")
    r = subprocess.run([sys.executable, "-m", "windseek.cli", "campaign", str(bad), "--out", str(out)],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "unknown scenario parameter 'windspeed'" in r.stderr
    assert not out.exists()
