"""Read a windseek ``.rrd`` recording back as numpy arrays (tests, review tooling).

Built on ``rerun.chunk.RrdReader``: the file is read once into memory (a few MB for a
typical run) and queried by entity path. Paths may be given with or without the leading
``/`` that rerun stores; the ones returned have none (``"wind/north/truth"``).

    from recording.read import RrdLog
    log = RrdLog("logs/run.rrd")
    log.entity_paths()                     # ['chem/threshold', 'chem/value', ..., 'world/vehicle']
    t, v = log.scalars("rotors/1")         # t [s] (N,), v (N,) sorted by sim_time
    t, p = log.vectors("world/vehicle", "Transform3D:translation")   # (N,), (N, 3)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from rerun.chunk import Chunk, RrdReader

from recording.rerun_log import TIMELINE

SCALARS = "Scalars:scalars"


def _norm(entity: str) -> str:
    return entity.strip("/")


class RrdLog:
    """One ``.rrd`` file: its recording chunks (by entity) and whether it carries a blueprint."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        reader = RrdReader(self.path)
        self.application_ids = [s.application_id for s in reader.recordings()]
        self.blueprint_count = len(reader.blueprints())
        self._blueprint_paths: list[str] | None = None
        self._reader = reader
        self._chunks: dict[str, list[Chunk]] = {}
        for chunk in reader.stream().to_chunks():
            self._chunks.setdefault(_norm(chunk.entity_path), []).append(chunk)

    # ------------------------------------------------------------------ discovery
    def entity_paths(self) -> list[str]:
        """Every entity path with data (static or temporal), sorted, without the leading '/'."""
        return sorted(p for p in self._chunks if p)

    def temporal_entity_paths(self, timeline: str = TIMELINE) -> list[str]:
        """Entity paths with data on ``timeline`` (leaves out style-only and static entities)."""
        return sorted(
            p for p, chunks in self._chunks.items() if p and any(timeline in c.timeline_names for c in chunks)
        )

    def timelines(self) -> set[str]:
        """Names of all timelines used by any chunk."""
        return {name for chunks in self._chunks.values() for c in chunks for name in c.timeline_names}

    def components(self, entity: str) -> set[str]:
        """Component column names of an entity (e.g. ``"Transform3D:translation"``)."""
        out: set[str] = set()
        for c in self._chunks.get(_norm(entity), []):
            rb = c.to_record_batch()
            out.update(f.name for f in rb.schema if f.metadata and f.metadata.get(b"rerun:kind") == b"data")
        return out

    def blueprint_entity_paths(self) -> list[str]:
        """Entity paths in the blueprint store(s) (views, containers, time panel); [] if none."""
        if self._blueprint_paths is None:
            paths: set[str] = set()
            for store in self._reader.blueprints():
                paths.update(_norm(c.entity_path) for c in self._reader.stream(store=store).to_chunks())
            self._blueprint_paths = sorted(paths)
        return self._blueprint_paths

    def blueprint_views(self) -> list[tuple[str, str, str]]:
        """Views of the blueprint(s): (class, origin, name), e.g. ("Spatial3D", "world", "world (NED)")."""
        views: list[tuple[str, str, str]] = []
        for store in self._reader.blueprints():
            for c in self._reader.stream(store=store).to_chunks():
                rb = c.to_record_batch()
                if "ViewBlueprint:class_identifier" not in rb.schema.names:
                    continue
                # Only the view columns: converting the blueprint's nanosecond timestamp column to
                # Python datetimes needs pandas, which is not a dependency.
                wanted = [n for n in ("ViewBlueprint:class_identifier", "ViewBlueprint:space_origin",
                                      "ViewBlueprint:display_name") if n in rb.schema.names]
                d = rb.select(wanted).to_pydict()
                for cls, origin, name in zip(
                    d["ViewBlueprint:class_identifier"],
                    d.get("ViewBlueprint:space_origin", [None] * rb.num_rows),
                    d.get("ViewBlueprint:display_name", [None] * rb.num_rows),
                    strict=True,
                ):
                    views.append((cls[0] if cls else "", origin[0] if origin else "", name[0] if name else ""))
        return views

    # ------------------------------------------------------------------ values
    def column(self, entity: str, component: str, timeline: str = TIMELINE) -> tuple[np.ndarray, list[Any]]:
        """Values of one component of an entity, sorted by time.

        Returns (t, values): t [s] (N,) for a duration timeline (NaN for static rows), and
        the per-row values as Python objects (lists for batches).
        """
        ts: list[float] = []
        vals: list[Any] = []
        for c in self._chunks.get(_norm(entity), []):
            rb = c.to_record_batch()
            names = rb.schema.names
            if component not in names:
                continue
            values = rb.column(component).to_pylist()
            if timeline in names:
                tcol = rb.column(timeline).cast("int64").to_numpy(zero_copy_only=False) * 1e-9
            else:
                tcol = np.full(len(values), np.nan)
            for ti, v in zip(tcol, values, strict=True):
                if v is not None:
                    ts.append(float(ti))
                    vals.append(v)
        order = np.argsort(np.asarray(ts), kind="stable")
        return np.asarray(ts)[order], [vals[i] for i in order]

    def scalars(self, entity: str, timeline: str = TIMELINE) -> tuple[np.ndarray, np.ndarray]:
        """A scalar series: t [s] (N,) and values (N,) (or (N, k) if each row holds k scalars)."""
        t, vals = self.column(entity, SCALARS, timeline)
        rows = [np.asarray(v, dtype=float).ravel() for v in vals]
        if not rows:
            return t, np.zeros(0)
        arr = np.vstack(rows) if len({len(r) for r in rows}) == 1 else np.array(rows, dtype=object)
        if arr.ndim == 2 and arr.shape[1] == 1:
            arr = arr[:, 0]
        return t, arr

    def vectors(self, entity: str, component: str, timeline: str = TIMELINE) -> tuple[np.ndarray, np.ndarray]:
        """A per-row 3-vector component (e.g. ``"Transform3D:translation"``): t (N,), (N, 3).

        For batch components (e.g. ``"Points3D:positions"``) the first instance of each row."""
        t, vals = self.column(entity, component, timeline)
        rows = [np.asarray(v[0] if v and isinstance(v[0], (list, tuple)) else v, dtype=float) for v in vals]
        return t, (np.vstack(rows) if rows else np.zeros((0, 3)))


def list_entity_paths(path: Path | str) -> list[str]:
    """Entity paths of a ``.rrd`` file (see :meth:`RrdLog.entity_paths`)."""
    return RrdLog(path).entity_paths()


def read_scalars(path: Path | str, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """Scalar series of one entity of a ``.rrd`` file: t [s], values (see :meth:`RrdLog.scalars`)."""
    return RrdLog(path).scalars(entity)


__all__ = ["SCALARS", "RrdLog", "list_entity_paths", "read_scalars"]
