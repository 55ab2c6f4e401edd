"""The recorder's plumbing: one ``rr.RecordingStream`` per run, the time line and buffered columns.

:class:`RecorderBase` owns the stream and nothing about what is drawn. High-rate rows (scalar
series, the vehicle pose, wind arrows) are buffered in Python lists and sent as columns
(``send_columns``) every ``series_flush_s`` of vehicle time: a buffered row costs a few
microseconds where a ``log`` call costs 30-100 us. It also keeps the values of the scalar series
it sent (decimated beyond ``VALUES_KEEP`` per series), so the layout can fit each plot's axis to
the data when the recording closes. :class:`CpuMeter` lets a caller say what recording cost it.
"""

from __future__ import annotations

import math
import os
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from recording.series import CARRIED_ARCHETYPE, carried_by, row_series
from recording.style import TIMELINE

#: Scalar values kept per series for fitting the plot ranges (thinned by 2 beyond this).
VALUES_KEEP = 20000


#: Archetypes that only style a time series: sent (deferred) only for a series that got rows.
SERIES_STYLES = frozenset({"SeriesLines", "SeriesPoints", "StateConfiguration"})


class ColumnBuffer:
    """Rows of one entity waiting to be sent as columns: times [s] and per-field values.

    ``width`` > 1 means every row holds that many instances (e.g. the four rotor speeds); the columns
    are then partitioned so each row stays one batch of ``width`` values. A field named like a
    column (``Chem:mg_m3``) of a scalar entity is a series carried in its rows (:mod:`recording.series`).
    ``convert`` maps a field to a function applied to its whole column (a float array) when it is
    sent: what a row stores (a concentration) becomes what is drawn (a colour) once per batch,
    not once per row.
    """

    __slots__ = ("archetype", "convert", "fields", "t", "width")

    def __init__(self, archetype: Any, width: int = 1,
                 convert: dict[str, Callable[[np.ndarray], np.ndarray]] | None = None) -> None:  # fmt: skip
        self.archetype = archetype
        self.width = width
        self.convert = convert or {}
        self.t: list[float] = []
        self.fields: dict[str, list[Any]] = {}

    def column(self, name: str) -> np.ndarray:
        """A field's buffered values as the array to send (colours: 0-255, not 0-1)."""
        fn = self.convert.get(name)
        if fn is not None:
            return fn(np.asarray(self.fields[name], dtype=float))
        return np.asarray(self.fields[name], dtype=np.uint8 if name == "colors" else float)

    def clear(self) -> None:
        self.t.clear()
        for v in self.fields.values():
            v.clear()


class SeriesValues:
    """The (t, value) pairs of one scalar series sent so far, for fitting plot ranges."""

    __slots__ = ("t", "v")

    def __init__(self) -> None:
        self.t = np.zeros(0)
        self.v = np.zeros(0)

    def add(self, t: np.ndarray, v: np.ndarray) -> None:
        self.t = np.concatenate([self.t, t])
        self.v = np.concatenate([self.v, v])
        if len(self.t) > VALUES_KEEP:
            self.t, self.v = self.t[::2], self.v[::2]


def _task_ids() -> set[str]:
    """Thread ids of this process (Linux /proc; empty elsewhere)."""
    try:
        return set(os.listdir("/proc/self/task"))
    except OSError:
        return set()


def _task_cpu_s(tid: str) -> float:
    """A thread's CPU time [s]: the scheduler's nanoseconds on the CPU (``schedstat``), else user +
    system time in clock ticks (``stat``: 10 ms steps, as much as a trial's rerun threads use)."""
    try:
        with open(f"/proc/self/task/{tid}/schedstat") as f:
            return int(f.read().split()[0]) * 1e-9
    except (OSError, IndexError, ValueError):
        pass
    try:
        with open(f"/proc/self/task/{tid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


class CpuMeter:
    """CPU time a caller spends recording: ``meter(fn, *args)`` runs ``fn`` and adds the calling
    thread's CPU time it took (``time.thread_time``: a system call, 1-2 us, twice per call). Calls are not
    nested; :meth:`report` counts a call in progress up to that moment (a recorder's ``close``
    reports its cost from inside, before the stream closes)."""

    def __init__(self) -> None:
        self.cpu_s = 0.0
        self.p0 = time.process_time()
        self._t_call: float | None = None  # thread_time at the start of the call in progress

    def __call__(self, fn: Callable[..., Any], *args: Any) -> Any:
        t0 = self._t_call = time.thread_time()
        try:
            return fn(*args)
        finally:
            self._t_call = None
            self.cpu_s += time.thread_time() - t0

    def report(self, rec: RecorderBase) -> dict[str, float]:
        """The recording's cost: the caller's part, rerun's threads, and the whole process since the
        meter started [CPU s] (for the ``recording_cost`` property; ``benchmarks/recording_cost.py``)."""
        cpu = self.cpu_s + (time.thread_time() - self._t_call if self._t_call is not None else 0.0)
        return {"recorder_cpu_s": round(cpu, 4), "rerun_cpu_s": round(rec.rerun_cpu_s(), 4),
                "process_cpu_s": round(time.process_time() - self.p0, 4)}  # fmt: skip


class RecorderBase:
    """A Rerun recording stream saved to ``path`` with its own recording id, and the buffers.

    Args:
        path: output ``.rrd`` file (parent folders are created).
        application_id: Rerun application id (the viewer keys its layouts by it).
        series_flush_s: vehicle seconds between two sends of the buffered rows (a live viewer lags
            by that much).
        recording_id: reuse an id (rewriting a finished recording); default: a fresh one.
        defer_static: keep the static data (styles, map furniture, the scene) until :meth:`_close_stream`
            and send it then, one chunk per entity, only the last of each kind (what the viewer shows
            anyway), and no series style for a series that never got a row. For a recording nobody
            watches live (a batch trial): every chunk costs the file ~3 kB of schema and index,
            whatever it holds.
        footer: end the file with rerun's footer, a manifest of every chunk (byte offsets, per-column
            time ranges) and the Arrow schema of every column, for random access without reading the
            whole file (a catalog, ``rerun.chunk.LazyStore``). It is a quarter of a trial's file (~260 kB,
            the schemas uncompressed) and the viewer reads a local file whole anyway: a batch trial
            leaves it out (``save(write_footer=False)``; rerun warns once per file, and ``rerun rrd
            optimize`` adds it back). The chunks are the same either way.
        shared_rows: series logged together share rows (:mod:`recording.series`; a row costs ~14 bytes
            besides its values); False: every series an entity of its own (the layout before 2026-12-06).

    Not thread-safe: one stream with its own current time; use it from one thread or one asyncio loop.
    """

    def __init__(self, path: Path | str, application_id: str = "windseek", *, series_flush_s: float = 0.5,
                 recording_id: str | None = None, defer_static: bool = False, footer: bool = True,
                 shared_rows: bool = True) -> None:  # fmt: skip
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.series_flush_s = float(series_flush_s)
        # A fresh id per instance: the default id is shared process-wide, which would merge two
        # recorders (or two test runs) into one recording.
        before = _task_ids()
        # Not watched live: rows wait in the batcher until a flush (the series' own, or close), so each
        # entity's logged rows become one chunk rather than one per 8 ms of wall time.
        batcher = rr.ChunkBatcherConfig.NEVER() if defer_static else None
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id or uuid.uuid4(),
                                      batcher_config=batcher)  # fmt: skip
        # Wall-clock "log_time" means nothing for a lockstep simulation and costs per call.
        self.rec.set_log_time_enabled(False)
        self.rec.save(self.path, write_footer=footer)
        self._rerun_tids = _task_ids() - before  # rerun's own threads (encoding, writing)
        self.closed = False
        self.t_first = math.inf
        self.t_last = -math.inf
        self._series: dict[str, ColumnBuffer] = {}
        self._values: dict[str, SeriesValues] = {}
        self._t_flush = -math.inf
        self.defer_static = bool(defer_static)
        self._static: dict[str, dict[str, Any]] = {}  # entity -> archetype name -> the latest one
        self._temporal: set[str] = set()  # entities with rows on the time line
        self._grouped: set[str] = set()  # series with rows in an entity of several (recording.series)
        self.shared_rows = bool(shared_rows)

    # ------------------------------------------------------------------ time
    def _seen(self, t: float) -> None:
        if t < self.t_first:
            self.t_first = t
        if t > self.t_last:
            self.t_last = t

    def _time(self, t: float) -> None:
        """Set the stream's time for the next ``log`` calls (vehicle seconds)."""
        t = float(t)
        self._seen(t)
        self.rec.set_time(TIMELINE, duration=t)

    @property
    def t_latest(self) -> float:
        """The latest time logged so far [s] (0 before any)."""
        return self.t_last if math.isfinite(self.t_last) else 0.0

    def log_at(self, t: float, entity: str, *data: Any) -> None:
        """``log`` one or more archetypes at vehicle time ``t`` [s]."""
        self._time(t)
        self._temporal.add(entity)
        self.rec.log(entity, *data)

    def log_static(self, entity: str, *data: Any) -> None:
        """Static data (no time): sent now, or kept until close with ``defer_static`` (a later archetype
        of the same kind on the same entity replaces the earlier, as a static log does)."""
        if not self.defer_static:
            self.rec.log(entity, *data, static=True)
            return
        slot = self._static.setdefault(entity, {})
        for d in data:
            slot[type(d).__name__] = d

    def send_columns(self, entity: str, t: np.ndarray, columns: Any) -> None:
        """Rows of ``entity`` at vehicle times ``t`` [s] (one chunk)."""
        self._temporal.add(entity)
        self.rec.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=columns)

    def _send_deferred_static(self) -> None:
        for entity, slot in self._static.items():
            kinds = list(slot)
            if entity not in self._temporal and all(k in SERIES_STYLES for k in kinds):
                continue  # the style of a series that never got a row draws nothing
            self.rec.log(entity, *slot.values(), static=True)
        self._static.clear()

    # ------------------------------------------------------------------ buffered rows
    def _push(self, entity: str, t: float, value: float | None) -> None:
        """Buffer one scalar (skipped when None or not finite: a gap, not a zero)."""
        if value is None:
            return
        v = float(value)
        if not math.isfinite(v):
            return
        # The hot path (tens of thousands of rows per run): no keyword dictionary, no archetype lookup.
        buf = self._series.get(entity)
        if buf is None:
            buf = self._series[entity] = ColumnBuffer(rr.Scalars)
            buf.fields["scalars"] = []
        t = float(t)
        if t > self.t_last:
            self.t_last = t
        if t < self.t_first:
            self.t_first = t
        buf.t.append(t)
        buf.fields["scalars"].append(v)

    def _buffer(self, entity: str, archetype: Any, width: int = 1,
                convert: dict[str, Callable[[np.ndarray], np.ndarray]] | None = None) -> ColumnBuffer:  # fmt: skip
        """The row buffer of ``entity``, made on first use (see :class:`ColumnBuffer`)."""
        buf = self._series.get(entity)
        if buf is None:
            buf = self._series[entity] = ColumnBuffer(archetype, width, convert)
        return buf

    def _push_row(self, entity: str, archetype: Any, t: float, width: int = 1, **fields: Any) -> None:
        """Buffer one temporal row of ``archetype`` (``width`` instances per row) for :meth:`flush_series`."""
        t = float(t)
        self._seen(t)
        buf = self._series.get(entity)
        if buf is None:
            buf = self._buffer(entity, archetype, width)
        buf.t.append(t)
        for name, value in fields.items():
            buf.fields.setdefault(name, []).append(value)

    def _maybe_flush(self, t: float) -> None:
        # Never with an infinite period (a batch trial sends its rows at close: inf - -inf >= inf sent
        # the first rows alone, one more chunk of ~1.2 kB for each entity with a row at the start).
        if t - self._t_flush >= self.series_flush_s and math.isfinite(self.series_flush_s):
            self.flush_series()
            self._t_flush = t

    def _push_scalars(self, entity: str, t: float, values: list[float],
                      carried: dict[str, float] | None = None) -> None:  # fmt: skip
        """Buffer one row of a scalar entity that holds several series (:mod:`recording.series`): its
        ``Scalars`` instances (a value that is not finite is sent as NaN: a gap) and the components it
        carries (column name -> value; every row of an entity gives the same ones)."""
        if not self.shared_rows:  # each series its own entity
            for name, v in zip(row_series(entity), values, strict=True):
                self._push(name, t, v)
            for comp, v in (carried or {}).items():
                self._push(carried_by(entity)[comp], t, v)
            return
        buf = self._series.get(entity)
        if buf is None:
            buf = self._series[entity] = ColumnBuffer(rr.Scalars, len(values))
            self._grouped.update(row_series(entity), carried_by(entity).values())
        t = float(t)
        self._seen(t)
        buf.t.append(t)
        buf.fields.setdefault("scalars", []).append([v if math.isfinite(v) else math.nan for v in map(float, values)])
        for comp, v in (carried or {}).items():
            buf.fields.setdefault(comp, []).append(float(v))

    def _scalar_columns(self, entity: str, buf: ColumnBuffer, t: np.ndarray) -> list[Any]:
        """The columns of a scalar entity's buffered rows; the values kept per series for the range fit."""
        v = np.asarray(buf.fields["scalars"], dtype=float).reshape(len(t), buf.width)
        cols = list(rr.Scalars.columns(scalars=v.ravel()).partition([buf.width] * len(t)) if buf.width > 1 else
                    rr.Scalars.columns(scalars=v[:, 0]))  # fmt: skip
        for k, name in enumerate(row_series(entity)):
            self._values.setdefault(name, SeriesValues()).add(t, v[:, k])
        carried = carried_by(entity)
        extra = {comp: buf.column(comp) for comp in buf.fields if comp in carried}
        for comp, col in extra.items():
            self._values.setdefault(carried[comp], SeriesValues()).add(t, col)
        if extra:
            cols += rr.DynamicArchetype.columns(archetype=CARRIED_ARCHETYPE,
                                                components={c.split(":", 1)[1]: col for c, col in extra.items()})
        return cols

    def flush_series(self) -> None:
        """Send the buffered rows now (done automatically every ``series_flush_s`` of vehicle time):
        one ``send_columns`` per entity for all its rows since the last flush."""
        for entity, buf in self._series.items():
            if not buf.t:
                continue
            t = np.asarray(buf.t)
            if buf.archetype is rr.Scalars:
                columns = self._scalar_columns(entity, buf, t)
            else:
                cols = {name: buf.column(name) for name in buf.fields}
                flat = {name: v.reshape(-1, *v.shape[2:]) for name, v in cols.items()} if buf.width > 1 else cols
                columns = buf.archetype.columns(**flat)
                if buf.width > 1:
                    columns = columns.partition([buf.width] * len(t))
            self.send_columns(entity, t, columns)
            buf.clear()

    def values(self, entity: str) -> tuple[np.ndarray, np.ndarray]:
        """The (t [s], value) pairs of a scalar series sent so far, by series name (thinned beyond
        ``VALUES_KEEP``)."""
        s = self._values.get(entity)
        return (s.t, s.v) if s is not None else (np.zeros(0), np.zeros(0))

    def has_series(self, entity: str) -> bool:
        """Whether any row of this entity (or series, :mod:`recording.series`) was sent or is buffered."""
        return entity in self._series or entity in self._grouped

    def rerun_cpu_s(self) -> float:
        """CPU seconds rerun's threads of this recording used so far (0 where /proc is missing)."""
        return sum(_task_cpu_s(t) for t in self._rerun_tids)

    # ------------------------------------------------------------------ properties and end
    def property(self, name: str, **values: Any) -> None:
        """A recording property (shown in the viewer's recording panel); None values are left out."""
        kept = {k: v for k, v in values.items() if v is not None}
        if kept:
            self.rec.send_property(name, rr.AnyValues(**kept))

    def _close_stream(self) -> None:
        self.flush_series()
        self._send_deferred_static()
        self.rec.flush()
        self.rec.disconnect()
        self.closed = True


__all__ = ["SERIES_STYLES", "VALUES_KEEP", "ColumnBuffer", "CpuMeter", "RecorderBase", "SeriesValues"]
