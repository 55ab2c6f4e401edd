"""Campaigns on a real Dask cluster: a ``dask scheduler`` and two ``dask worker`` processes on localhost
(ephemeral ports), the campaign run by the real command line. A worker killed mid-campaign: its
missions finish on the other, nothing lost, nothing counted twice. The campaign process killed and
re-run: finished missions are skipped. A mission that raises: retried once, recorded as an error, the
rest flown. An unreachable scheduler: one line, before any work."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from datetime import datetime
from pathlib import Path

import pytest
from link_support import free_port

from mission.campaign.grid import expand
from mission.campaign.spec import load_campaign
from mission.campaign.store import ResultStore, read_results

pytestmark = pytest.mark.e2e

# 24 short missions (the source 15-25 m upwind, the oracle wind: about a second each here).
SPEC = """
[campaign]
name = "dask-test"
scenarios = ["open-field"]
strategies = ["surge-cast", "anemotaxis"]
winds = ["oracle"]
seeds = { start = 100, count = 4 }
time_limit_s = 60
[campaign.scenario]
start_distance_m = [15, 20, 25]
"plume.warmup_s" = 20
"""
N_MISSIONS = 24


def _start(cmd: list[str], log: Path) -> subprocess.Popen:
    # A session of its own: killing the group kills a worker's nanny and its worker process together.
    return subprocess.Popen(cmd, stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=True)


def _kill(p: subprocess.Popen) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(p.pid, signal.SIGKILL)
    p.wait(timeout=30)


def _wait(what: str, cond, timeout: float, procs: tuple[subprocess.Popen, ...] = ()) -> None:  # noqa: ANN001
    t_end = time.monotonic() + timeout
    while not cond():
        for p in procs:
            assert p.poll() is None, f"{what}: a process exited early ({p.args})"
        assert time.monotonic() < t_end, f"timed out after {timeout:g} s waiting for {what}"
        time.sleep(0.2)


class Cluster:
    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.file = tmp / "scheduler.json"
        cmd = [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
               "--scheduler-file", str(self.file)]  # fmt: skip
        self.scheduler = _start(cmd, tmp / "scheduler.log")
        _wait("the scheduler file", self.file.exists, 60, (self.scheduler,))
        self.workers = {name: self.worker(name) for name in ("wA", "wB")}

    def worker(self, name: str) -> subprocess.Popen:
        return _start([sys.executable, "-m", "dask", "worker", "--scheduler-file", str(self.file), "--host",
                       "127.0.0.1", "--nthreads", "1", "--nworkers", "1", "--no-dashboard", "--name", name,
                       "--preload", "mission.campaign.worker", "--death-timeout", "60"],
                      self.tmp / f"{name}.log")  # fmt: skip

    def addresses(self) -> dict[str, str]:
        """{worker name: address} as the scheduler knows them."""
        from distributed import Client

        with Client(scheduler_file=str(self.file), timeout=20) as c:
            return {w["name"]: addr for addr, w in c.scheduler_info()["workers"].items()}

    def close(self) -> None:
        for p in [*self.workers.values(), self.scheduler]:
            _kill(p)


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[Cluster]:
    c = Cluster(tmp_path)
    try:
        _wait("two workers", lambda: len(c.addresses()) == 2, 180, tuple(c.workers.values()))
        yield c
    finally:
        c.close()


def _campaign(tmp: Path, scheduler: str, out: Path) -> subprocess.Popen:
    spec = tmp / "spec.toml"
    spec.write_text(SPEC)
    return subprocess.Popen([sys.executable, "-m", "windseek.cli", "campaign", str(spec), "--scheduler", scheduler,
                             "--out", str(out), "--flush", "0.3", "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # fmt: skip


def _rows(out: Path) -> int:
    try:
        return read_results(out, dedupe=False).num_rows
    except Exception:  # noqa: BLE001 -- not created yet
        return 0


def test_a_worker_killed_mid_campaign_loses_nothing(cluster: Cluster, tmp_path: Path) -> None:
    addr = cluster.addresses()
    out = tmp_path / "res"
    run = _campaign(tmp_path, str(cluster.file), out)
    try:
        _wait("3 finished missions", lambda: _rows(out) >= 3, 400, (run,))
        _kill(cluster.workers["wA"])  # mid-mission: both workers are busy while missions are queued
        t_kill = time.time()
        _, err = run.communicate(timeout=600)
    finally:
        _kill(run)
    assert run.returncode == 0, err
    assert f"{N_MISSIONS} missions, 0 already finished" in err and "0 errors" in err
    raw = read_results(out, dedupe=False)
    assert raw.num_rows == N_MISSIONS  # nothing counted twice
    keys = raw.column("key").to_pylist()
    assert sorted(keys) == sorted(t.key for t in expand(load_campaign(tmp_path / "spec.toml")))  # nothing lost
    assert set(raw.column("status").to_pylist()) == {"ok"}
    workers = raw.column("worker").to_pylist()
    n_a = workers.count(addr["wA"])
    assert n_a < N_MISSIONS - 3 and workers.count(addr["wB"]) == N_MISSIONS - n_a
    stamps = [datetime.fromisoformat(s).timestamp() for s in raw.column("finished_at").to_pylist()]
    assert any(s >= t_kill - 1 for s in stamps)  # missions finished after the kill (on wB)


def test_a_killed_campaign_resumes_and_skips_finished_missions(cluster: Cluster, tmp_path: Path) -> None:
    out = tmp_path / "res"
    run = _campaign(tmp_path, str(cluster.file), out)
    try:
        _wait("4 finished missions", lambda: _rows(out) >= 4, 400, (run,))
        os.killpg(run.pid, signal.SIGKILL)
        run.wait(timeout=30)
    finally:
        _kill(run)
    first = read_results(out)
    done = set(first.column("key").to_pylist())
    assert 4 <= len(done) < N_MISSIONS
    run = _campaign(tmp_path, str(cluster.file), out)
    try:
        _, err = run.communicate(timeout=600)
    finally:
        _kill(run)
    assert run.returncode == 0, err
    assert f"{N_MISSIONS} missions, {len(done)} already finished" in err
    assert f"{N_MISSIONS - len(done)} to fly" in err
    raw = read_results(out, dedupe=False)
    assert raw.num_rows == N_MISSIONS and len(set(raw.column("key").to_pylist())) == N_MISSIONS
    before = dict(zip(first.column("key").to_pylist(), first.column("finished_at").to_pylist(), strict=True))
    after = dict(zip(raw.column("key").to_pylist(), raw.column("finished_at").to_pylist(), strict=True))
    assert all(after[k] == v for k, v in before.items())  # the first run's rows are kept, not re-flown


def test_a_failing_mission_is_retried_once_and_recorded(cluster: Cluster, tmp_path: Path) -> None:
    from distributed import Client

    from mission.campaign.execute import execute

    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.replace("count = 4", "count = 1"))
    tasks = expand(load_campaign(spec))
    bad = replace(tasks[0], key="0" * 20, scenario_table={**tasks[0].scenario_table,
                                                        "wind": {"speed_m_s": -1.0, "from_deg": 0.0}})  # fmt: skip
    store = ResultStore(tmp_path / "res", "dask-test", flush_s=0.2).open()
    with Client(scheduler_file=str(cluster.file), timeout=20) as client:
        rep = execute(client, [bad, *tasks], store, "test", progress=False, retries=1)
        story = client.run_on_scheduler(lambda dask_scheduler: [t[1:3] for t in
                                                                dask_scheduler.story("windseek-" + "0" * 20)])
    store.close()
    assert rep.done == len(tasks) + 1 and rep.errors == 1
    assert story.count(("waiting", "processing")) == 2 and story.count(("processing", "erred")) == 1  # ran twice
    table = read_results(tmp_path / "res")
    rows = {r["key"]: r for r in table.to_pylist()}
    assert rows["0" * 20]["status"] == "error" and "wind.speed_m_s = -1.0" in rows["0" * 20]["error"]
    assert all(rows[t.key]["status"] == "ok" for t in tasks)


def test_an_unreachable_scheduler_is_one_line_before_any_work(tmp_path: Path) -> None:
    port = free_port(socket.SOCK_STREAM)  # a free port nobody listens on
    out = tmp_path / "res"
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    t0 = time.monotonic()
    cmd = [sys.executable, "-m", "windseek.cli", "campaign", str(spec), "--scheduler", f"tcp://127.0.0.1:{port}",
           "--out", str(out)]  # fmt: skip
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert r.returncode == 2
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith(f"windseek campaign: error: cannot reach the Dask scheduler tcp://127.0.0.1:{port} within")
    assert not out.exists() and time.monotonic() - t0 < 120
    r = subprocess.run([sys.executable, "-m", "windseek.cli", "campaign", str(spec), "--scheduler", "nowhere"],
                       capture_output=True, text=True, timeout=180)  # fmt: skip
    assert r.returncode == 2 and "expected tcp://HOST:PORT" in r.stderr


def test_results_of_an_incompatible_version_are_refused_before_any_work(tmp_path: Path) -> None:
    out = tmp_path / "res"
    out.mkdir()
    (out / "campaign.json").write_text(json.dumps({"schema_version": 99, "campaign": "dask-test",
                                                   "windseek_version": "9.9"}))  # fmt: skip
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    r = subprocess.run([sys.executable, "-m", "windseek.cli", "campaign", str(spec), "--out", str(out)],
                       capture_output=True, text=True, timeout=180)  # fmt: skip
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "written with results schema 99 (windseek 9.9)" in r.stderr
