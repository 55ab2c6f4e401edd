"""Campaign results: rows of real (short) missions appended to Parquet, resumed by key, never counted
twice; incompatible folders refused in one line; the report's statistics and plots."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from mission.campaign.grid import expand
from mission.campaign.report import group_columns, markdown, summarize_groups, wilson
from mission.campaign.rows import error_row
from mission.campaign.spec import CampaignError, load_campaign
from mission.campaign.store import MANIFEST, ResultStore, read_results
from mission.campaign.worker import run_task

# Short missions: the source 15 or 25 m upwind, the plume formed for 20 s, the oracle wind (cheap:
# no estimator), 60 s limit. Seeds 100-102 (development seeds).
SPEC = """
[campaign]
name = "short"
scenarios = ["open-field"]
strategies = ["surge-cast", "anemotaxis"]
winds = ["oracle"]
seeds = [100, 101, 102]
time_limit_s = 60
[campaign.scenario]
start_distance_m = [15, 25]
"plume.warmup_s" = 20
"""


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> tuple[list, list[dict]]:
    d = tmp_path_factory.mktemp("short")
    (d / "short.toml").write_text(SPEC)
    tasks = expand(load_campaign(d / "short.toml"))
    return tasks, [run_task(t) for t in tasks]


def test_rows_hold_configuration_outcome_and_figures(flown: tuple[list, list[dict]]) -> None:
    tasks, rows = flown
    assert len(rows) == 12
    for t, r in zip(tasks, rows, strict=True):
        assert r["key"] == t.key and r["status"] == "ok" and r["seed"] == t.seed
        assert r["p.start_distance_m"] == t.params["start_distance_m"]
        assert r["start_distance_m"] == pytest.approx(t.params["start_distance_m"], abs=0.5)  # start ~ home
        assert math.hypot(r["source_n"], r["source_e"]) == pytest.approx(t.params["start_distance_m"])
        assert json.loads(r["scenario_config"])["plume"]["warmup_s"] == 20
        assert json.loads(r["strategy_config"])["altitude_m"] > 0
        assert r["cpu_s"] > 0 and r["rss_mb"] > 50 and r["windseek_version"]
        if r["success"]:
            assert r["cause"] == "" and r["error_m"] <= 5.0 and r["declare_ratio"] >= r["reach_ratio"] > 0
        else:
            assert r["cause"] in ("declared-far", "timeout", "geofence", "crash", "takeoff")
        assert 0.3 < r["wind_rmse_h"] < 5.0  # the oracle's mean wind against the turbulent truth
    assert 3 <= sum(r["success"] for r in rows) <= 12


def test_store_appends_resumes_and_never_counts_twice(tmp_path: Path, flown: tuple[list, list[dict]]) -> None:
    _, rows = flown
    out = tmp_path / "res"
    store = ResultStore(out, "short", flush_s=1e9, flush_rows=4).open()
    for r in rows[:6]:
        store.add(r)
    assert len(list(out.glob("part-*.parquet"))) == 1  # written at the 4th row; 2 buffered
    store.flush()
    assert set(store.finished()) == {r["key"] for r in rows[:6]}
    store.close(compact=False)
    # a second run: the finished keys are skipped; an error row for a key that later succeeds is superseded
    store = ResultStore(out, "short", flush_s=1e9, flush_rows=100).open()
    assert set(store.finished()) == {r["key"] for r in rows[:6]}
    store.add(rows[0])  # a duplicate (as after a merge cut short)
    for r in rows[6:]:
        store.add(r)
    store.close(compact=False)
    raw = read_results(out, dedupe=False)
    assert raw.num_rows == 13
    table = read_results(out)
    assert table.num_rows == 12 and sorted(table.column("key").to_pylist()) == sorted(r["key"] for r in rows)
    store = ResultStore(out, "short").open()
    store.close()  # merges the parts
    assert len(list(out.glob("part-*.parquet"))) == 1
    assert read_results(out, dedupe=False).num_rows == 12


def test_back_to_back_runs_in_one_process_keep_every_part(tmp_path: Path, flown: tuple[list, list[dict]]) -> None:
    # Two runs within the same second used to name their first part alike, and the second replaced the first.
    _, rows = flown
    out = tmp_path / "res"
    for chunk in (rows[:2], rows[2:4], rows[4:6]):
        store = ResultStore(out, "short", flush_s=1e9).open()
        for r in chunk:
            store.add(r)
        store.close(compact=False)
    assert len(list(out.glob("part-*.parquet"))) == 3
    assert read_results(out, dedupe=False).column("key").to_pylist() == [r["key"] for r in rows[:6]]


def test_error_rows_are_superseded_by_a_later_success(tmp_path: Path, flown: tuple[list, list[dict]]) -> None:
    tasks, rows = flown
    store = ResultStore(tmp_path / "r", "short").open()
    store.add(error_row(tasks[0], "RuntimeError: boom"))
    store.flush()
    assert store.finished() == {}  # an error is flown again on the next run
    store.add(rows[0])
    store.close()
    t = read_results(tmp_path / "r")
    assert t.num_rows == 1 and t.column("status").to_pylist() == ["ok"]


def test_incompatible_or_busy_results_are_refused(tmp_path: Path, flown: tuple[list, list[dict]]) -> None:
    _, rows = flown
    out = tmp_path / "res"
    store = ResultStore(out, "short").open()
    store.add(rows[0])
    store.flush()
    with pytest.raises(CampaignError, match="another campaign run is writing"):
        ResultStore(out, "short").open()
    store.close()
    with pytest.raises(CampaignError, match="holds the results of campaign 'short', not 'other'"):
        ResultStore(out, "other").open()
    man = json.loads((out / MANIFEST).read_text())
    (out / MANIFEST).write_text(json.dumps({**man, "schema_version": 0}))
    with pytest.raises(CampaignError, match="written with results schema 0") as e:
        ResultStore(out, "short").open()
    assert "\n" not in str(e.value)
    (out / MANIFEST).write_text(json.dumps(man))
    part = next(out.glob("part-*.parquet"))
    t = pq.read_table(part)
    pq.write_table(t.replace_schema_metadata({b"windseek.campaign.schema_version": b"7"}), part)
    with pytest.raises(CampaignError, match="results schema 7"):
        read_results(out)
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "x.txt").write_text("x")
    with pytest.raises(CampaignError, match="not a campaign results folder"):
        ResultStore(tmp_path / "junk", "short").open()


def test_wilson_interval() -> None:
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson(5, 10)
    assert (lo, hi) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    lo, hi = wilson(45, 50)
    assert (lo, hi) == pytest.approx((0.7864, 0.9565), abs=1e-4)
    assert all(math.isnan(v) for v in wilson(0, 0))


def test_report_groups_match_the_rows(tmp_path: Path, flown: tuple[list, list[dict]]) -> None:
    _, rows = flown
    store = ResultStore(tmp_path / "res", "short").open()
    for r in rows:
        store.add(r)
    store.close()
    table = read_results(tmp_path / "res")
    by = group_columns(table, None)
    assert by == ["scenario", "strategy", "wind", "p.start_distance_m"]  # warmup_s is fixed: not a group
    groups = summarize_groups(table, by)
    assert len(groups) == 4
    for g in groups:
        mine = [r for r in rows
                if r["strategy"] == g["strategy"] and r["p.start_distance_m"] == g["p.start_distance_m"]]
        won = [r for r in mine if r["success"]]
        assert g["missions"] == len(mine) == 3 and g["successes"] == len(won)
        assert (g["success_lo"], g["success_hi"]) == pytest.approx(wilson(len(won), 3))
        if won:
            assert g["declare_median"] == pytest.approx(np.median([r["declare_ratio"] for r in won]))
            assert g["reach_p90"] == pytest.approx(np.percentile([r["reach_ratio"] for r in won], 90))
    md = markdown(groups, by)
    assert md.count("\n") == 5 and "| start_distance_m |" in md.splitlines()[0]
    with pytest.raises(CampaignError, match="--by speed: no such column"):
        group_columns(table, ["speed"])


def test_cli_report_prints_tables_and_writes_plots(tmp_path: Path, flown: tuple[list, list[dict]]) -> None:
    _, rows = flown
    store = ResultStore(tmp_path / "res", "short").open()
    for r in rows:
        store.add(r)
    store.close()
    cmd = [sys.executable, "-m", "windseek.cli", "campaign", "report", str(tmp_path / "res")]
    r = subprocess.run([*cmd, "--by", "strategy,start_distance_m", "--markdown"], capture_output=True, text=True,
                       timeout=180)  # fmt: skip
    assert r.returncode == 0, r.stderr
    head = r.stdout.splitlines()[0]
    assert head.startswith("| strategy | start_distance_m | n | success % [95 % CI]")
    assert len(r.stdout.strip().splitlines()) == 2 + 4
    pngs = sorted((tmp_path / "res" / "plots").glob("*.png"))
    assert [p.name for p in pngs] == ["declared-map.png", "sweep-start_distance_m.png"]
    for p in pngs:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    r = subprocess.run([*cmd, "--by", "speed", "--no-plots"], capture_output=True, text=True, timeout=180)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--by speed: no such column" in r.stderr
    r = subprocess.run([sys.executable, "-m", "windseek.cli", "campaign", "report", str(tmp_path / "none")],
                       capture_output=True, text=True, timeout=180)  # fmt: skip
    assert r.returncode == 2 and "no such results folder" in r.stderr


def test_progress_lines_say_done_rate_and_eta() -> None:
    import time

    from mission.campaign.execute import _Progress

    lines: list[str] = []
    progress = _Progress("camp", 3, enabled=True, out=lines.append, every_s=0.0)
    progress.tty = False  # the plain lines of a batch job's log, not the terminal bar
    with progress as bar:
        bar.t0 = time.monotonic() - 10.0  # one mission done 10 s after the start: 360 per hour, 20 s to go
        bar.advance(0)
        bar.advance(1)
        bar.advance(1)
    assert len(lines) == 3
    first = lines[0]
    assert first.startswith("camp: 1/3 missions, ") and first.endswith(", 0 errors")
    rate = float(first.split(", ")[1].removesuffix("/h").replace(",", ""))
    assert 355 <= rate <= 360 and "ETA 0:20" in first
    assert lines[1].startswith("camp: 2/3 missions") and "ETA 0:05" in lines[1] and lines[1].endswith("1 errors")
    assert lines[2].startswith("camp: 3/3 missions") and "ETA 0:00" in lines[2]
    silent: list[str] = []
    with _Progress("camp", 3, enabled=False, out=silent.append) as bar:
        bar.advance(0)
    assert silent == []
