"""Campaign results on disk: a folder of Parquet files, appended to as missions finish.

``RESULTS/`` holds ``campaign.json`` (the campaign's name and the results schema version) and
``part-*.parquet`` files. A run buffers finished rows and writes them as a new part every few
seconds, atomically (written under a temporary name, then renamed), so a run that is killed
loses at most the last few seconds of missions, which the next run flies again. At the end of a
run the parts are merged into one. Readers keep one row per key (a finished row over an error
row, then the first written), so a mission is never counted twice, even if a merge was cut short.

One run at a time writes a folder (an exclusive ``flock`` on ``RESULTS/.lock``, released by the
kernel if the run dies). A folder written by another results schema, or by another campaign, is
refused with one line before anything runs.
"""

from __future__ import annotations

import fcntl
import json
import os
import time
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from mission.campaign.rows import SCHEMA_VERSION, to_table, windseek_version
from mission.campaign.spec import CampaignError

MANIFEST = "campaign.json"
META_KEY = b"windseek.campaign.schema_version"


def _parts(path: Path) -> list[Path]:
    return sorted(path.glob("part-*.parquet"))


def check_results(path: Path, campaign: str | None = None) -> dict[str, Any]:
    """The manifest of an existing results folder; CampaignError if it is not one this windseek can use."""
    man = path / MANIFEST
    if not man.is_file():
        raise CampaignError(f"{path}: not a campaign results folder (no {MANIFEST})")
    try:
        info = json.loads(man.read_text())
        version = int(info["schema_version"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise CampaignError(f"{path}/{MANIFEST}: unreadable ({e})") from None
    if version != SCHEMA_VERSION:
        raise CampaignError(f"{path}: written with results schema {version} (windseek "
                            f"{info.get('windseek_version', '?')}); this windseek reads schema {SCHEMA_VERSION}: "
                            "use a new --out folder")  # fmt: skip
    if campaign is not None and info.get("campaign") != campaign:
        raise CampaignError(f"{path}: holds the results of campaign {info.get('campaign')!r}, not {campaign!r}: "
                            "use another --out folder")  # fmt: skip
    return dict(info)


def read_results(path: str | Path, dedupe: bool = True) -> pa.Table:
    """Every row of a results folder (or one Parquet file), one per key unless ``dedupe`` is False."""
    p = Path(path)
    if p.is_file():
        files = [p]
    elif p.is_dir():
        check_results(p)
        files = _parts(p)
    else:
        raise CampaignError(f"{p}: no such results folder or Parquet file")
    tables = []
    for f in files:
        try:
            t = pq.read_table(f)
        except (OSError, pa.ArrowException) as e:
            raise CampaignError(f"{f}: not a readable Parquet file ({e})") from None
        meta = t.schema.metadata or {}
        if META_KEY not in meta or int(meta[META_KEY]) != SCHEMA_VERSION:
            raise CampaignError(f"{f}: results schema {meta.get(META_KEY, b'?').decode()}; this windseek reads "
                                f"schema {SCHEMA_VERSION}")  # fmt: skip
        tables.append(t.replace_schema_metadata(None))
    if not tables:
        return to_table([])
    table = pa.concat_tables(tables, promote_options="permissive")
    return _dedupe(table) if dedupe else table


def _dedupe(table: pa.Table) -> pa.Table:
    keys = table.column("key").to_pylist()
    status = table.column("status").to_pylist()
    chosen: dict[str, int] = {}
    for i, (k, s) in enumerate(zip(keys, status, strict=True)):
        j = chosen.get(k)
        if j is None or (s == "ok" and status[j] != "ok"):
            chosen[k] = i
    return table.take(sorted(chosen.values()))


def finished_missions(path: Path, campaign: str) -> dict[str, str]:
    """{key: config_hash} of the missions flown in the results folder ``path`` (status ok); {} if it
    does not exist yet. CampaignError if it cannot be used for ``campaign``."""
    if not path.exists() or (path.is_dir() and not any(path.iterdir())):
        return {}
    if not path.is_dir():
        raise CampaignError(f"{path}: exists and is not a folder")
    check_results(path, campaign)
    table = read_results(path)
    if table.num_rows == 0:
        return {}
    keys, hashes = table.column("key").to_pylist(), table.column("config_hash").to_pylist()
    ok = [s == "ok" for s in table.column("status").to_pylist()]
    return {k: h for k, h, good in zip(keys, hashes, ok, strict=True) if good}


class ResultStore:
    """The results folder of one campaign run (see the module docstring).

    Args:
        path: the folder (created if missing).
        campaign: the campaign's name (a folder of another campaign is refused).
        flush_s: write buffered rows at least this often [s]; flush_rows: or when this many are buffered.
    """

    def __init__(self, path: str | Path, campaign: str, flush_s: float = 10.0, flush_rows: int = 200) -> None:
        self.path = Path(path)
        self.campaign = campaign
        self.flush_s, self.flush_rows = float(flush_s), int(flush_rows)
        self._rows: list[dict[str, Any]] = []
        self._last = time.monotonic()
        self._seq = 0
        # Part names must never collide: two stores of one process within one second (a resumed run,
        # a test) would otherwise replace each other's first part and lose its rows. The store's
        # creation time [ns] keeps the names unique and in the order the rows were written.
        self._token = f"{time.time_ns():016x}"
        self._lock_fd: int | None = None
        self.written = 0

    def open(self) -> ResultStore:
        """Create or check the folder and take its lock (CampaignError if in use or incompatible)."""
        if self.path.exists() and not self.path.is_dir():
            raise CampaignError(f"{self.path}: exists and is not a folder")
        if self.path.is_dir() and any(self.path.iterdir()):
            check_results(self.path, self.campaign)
        else:
            self.path.mkdir(parents=True, exist_ok=True)
            info = {"schema_version": SCHEMA_VERSION, "campaign": self.campaign, "windseek_version": windseek_version(),
                    "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}  # fmt: skip
            tmp = self.path / f".{MANIFEST}.tmp"
            tmp.write_text(json.dumps(info, indent=1) + "\n")
            os.replace(tmp, self.path / MANIFEST)
        fd = os.open(self.path / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise CampaignError(f"{self.path}: another campaign run is writing these results") from None
        self._lock_fd = fd
        return self

    def finished(self) -> dict[str, str]:
        """{key: config_hash} of the missions already flown (status ok)."""
        return finished_missions(self.path, self.campaign)

    def add(self, row: dict[str, Any]) -> None:
        """Buffer a row; written when the buffer is old or large enough."""
        self._rows.append(row)
        if len(self._rows) >= self.flush_rows or time.monotonic() - self._last >= self.flush_s:
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows as a new part file (atomically)."""
        self._last = time.monotonic()
        if not self._rows:
            return
        self._write(to_table(self._rows), self._stem(f"{self._seq:05d}"))
        self.written += len(self._rows)
        self._seq += 1
        self._rows = []

    def _stem(self, what: str) -> str:
        """A part's unique name: time, process, this store's creation time [ns], then ``what``."""
        return f"part-{time.strftime('%Y%m%dT%H%M%S')}-{os.getpid()}-{self._token}-{what}"

    def _write(self, table: pa.Table, stem: str) -> Path:
        meta = {META_KEY: str(SCHEMA_VERSION).encode(), b"windseek.campaign.name": self.campaign.encode()}
        tmp = self.path / f".{stem}.tmp"
        pq.write_table(table.replace_schema_metadata(meta), tmp, compression="zstd")
        final = self.path / f"{stem}.parquet"
        os.replace(tmp, final)
        return final

    def compact(self) -> None:
        """Merge every part into one (one row per key); readers tolerate a merge cut short."""
        parts = _parts(self.path)
        if len(parts) <= 1:
            return
        merged = self._write(read_results(self.path), self._stem("merged"))
        for p in parts:
            if p != merged:
                p.unlink()

    def close(self, compact: bool = True) -> None:
        """Flush, merge the parts and release the lock."""
        try:
            self.flush()
            if compact:
                self.compact()
        finally:
            if self._lock_fd is not None:
                os.close(self._lock_fd)
                self._lock_fd = None
