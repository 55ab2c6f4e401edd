"""Read a windseek ``.rrd`` recording back as numpy arrays (tests, review tooling).

Built on ``rerun.chunk.RrdReader``: the file is read once into memory (a few MB for a
typical run) and queried by entity path. Paths may be given with or without the leading
``/`` that rerun stores; the ones returned have none (``"wind/north/truth"``).

    from recording.read import RrdLog
    log = RrdLog("logs/run.rrd")
    log.entity_paths()                     # ['chem/log10', ..., 'rotors', ..., 'world/vehicle']
    t, v = log.scalars("rotors/1")         # a series by name, wherever stored: t [s] (N,), v (N,) by time
    log.series()                           # every scalar series' name: [..., 'chem/value', ..., 'rotors/1', ...]
    t, lo, hi = log.band("wind/north/band")  # the +-2 sigma band's edges
    t, p = log.vectors("world/vehicle", "Transform3D:translation")   # (N,), (N, 3)
    t, imgs = log.images("map/posterior/image")   # H x W x 4 uint8 each, raw or PNG
    log.summary()                          # the RunSummary the recording carries
    log.states("phases/mission")           # [(t, "take-off"), (t, "search"), ...]
    log.layout()                           # the Layout facts (plot ranges, map extent, ...)
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
from rerun.chunk import Chunk, RrdReader

from recording.layout import Layout
from recording.png import decode_png
from recording.series import ROWS, Storage, carried_by, row_series, storage
from recording.style import TIMELINE
from recording.summary import RunSummary

SCALARS = "Scalars:scalars"


def _norm(entity: str) -> str:
    return entity.strip("/")


class RrdLog:
    """One ``.rrd`` file: its recording chunks (by entity) and whether it carries a blueprint."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        with warnings.catch_warnings():  # a batch trial's file has no footer: read whole, as here anyway
            warnings.filterwarnings("ignore", message="RRD file has no footer")
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

    def _final_blueprint(self) -> Any:
        """The blueprint store sent last (a recorder sends one at the start and the final one at close)."""
        best, best_t = None, -1
        for store in self._reader.blueprints():
            t = -1
            for c in self._reader.stream(store=store).to_chunks():
                rb = c.to_record_batch()
                if "log_time" in rb.schema.names and rb.num_rows:
                    t = max(t, max(v or -1 for v in rb.column("log_time").cast("int64").to_pylist()))
            if t > best_t:
                best, best_t = store, t
        return best

    def blueprint_views(self) -> list[tuple[str, str, str]]:
        """Views of the final blueprint: (class, origin, name), e.g. ("2D", "map", "map (north up)")."""
        views: list[tuple[str, str, str]] = []
        final = self._final_blueprint()
        for store in [final] if final is not None else []:
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
                    views.append((cls[0] if cls else "", _norm(origin[0]) if origin else "", name[0] if name else ""))
        return views

    def blueprint_view_contents(self) -> dict[str, list[str]]:
        """Origin -> the contents query of each view of the final blueprint (e.g. ``{"map":
        ["$origin/**", "- $origin/colorbar/**"]}``); views sharing an origin keep the last."""
        origins: dict[str, str] = {}
        queries: dict[str, list[str]] = {}
        final = self._final_blueprint()
        for c in self._reader.stream(store=final).to_chunks() if final is not None else []:
            rb = c.to_record_batch()
            path = _norm(c.entity_path)
            if "ViewBlueprint:space_origin" in rb.schema.names:
                for v in rb.column("ViewBlueprint:space_origin").to_pylist():
                    if v:
                        origins[path] = _norm(v[0])
            if "ViewContents:query" in rb.schema.names:
                for v in rb.column("ViewContents:query").to_pylist():
                    if v is not None:
                        queries[path.removesuffix("/ViewContents")] = [str(q) for q in v]
        return {origins[p]: q for p, q in queries.items() if p in origins}

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

    def series(self) -> list[str]:
        """The names of every scalar series with rows, those sharing rows included (:mod:`recording.series`)."""
        out: set[str] = set()
        for e in self.temporal_entity_paths():
            comps = self.components(e)
            if SCALARS in comps:
                out.update(row_series(e) if e in ROWS else (e,))
            out.update(s for c, s in carried_by(e).items() if c in comps)
        return sorted(out)

    def scalars(self, entity: str, timeline: str = TIMELINE) -> tuple[np.ndarray, np.ndarray]:
        """A scalar series by name: t [s] (N,) and values (N,) (or (N, k) if each row holds k scalars).

        A series sharing rows with others (``rotors/2``, ``chem/value``: :mod:`recording.series`) is read
        where it is stored; a recording made before they shared rows has it as an entity of its own."""
        e = _norm(entity)
        where = storage(e)
        if where != Storage(e, SCALARS, None) and e not in self._chunks:
            return self._stored(where, timeline)
        t, vals = self.column(e, SCALARS, timeline)
        rows = [np.asarray(v, dtype=float).ravel() for v in vals]
        if not rows:
            return t, np.zeros(0)
        arr = np.vstack(rows) if len({len(r) for r in rows}) == 1 else np.array(rows, dtype=object)
        if arr.ndim == 2 and arr.shape[1] == 1:
            arr = arr[:, 0]
        return t, arr

    def _stored(self, where: Storage, timeline: str) -> tuple[np.ndarray, np.ndarray]:
        """One series of the rows of an entity that holds several: no value where it has none (NaN)."""
        t, vals = self.column(where.entity, where.component, timeline)
        i = 0 if where.instance is None else where.instance
        v = np.array([float(x[i]) if isinstance(x, list) else float(x) for x in vals])
        ok = np.isfinite(v)
        return t[ok], v[ok]

    def band(self, entity: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A +-2 sigma band (``wind/<axis>/band``, written as two rows per sample): t [s] (N,), lower
        and upper edge (N,) each."""
        t, v = self.scalars(entity)
        n = len(t) // 2
        a, b = v[0 : 2 * n : 2], v[1 : 2 * n : 2]
        return t[0 : 2 * n : 2], np.minimum(a, b), np.maximum(a, b)

    def images(self, entity: str, timeline: str = TIMELINE) -> tuple[np.ndarray, list[np.ndarray]]:
        """An image entity's pixels: t [s] (N,) and per row an H x W x C uint8 array, whether it was sent
        raw (``rr.Image``, 8-bit channels) or encoded (``rr.EncodedImage``, a PNG: decoded to RGBA)."""
        t_raw, bufs = self.column(entity, "Image:buffer", timeline)
        _, fmts = self.column(entity, "Image:format", timeline)
        out: list[tuple[float, np.ndarray]] = []
        for ti, buf, fmt in zip(t_raw, bufs, fmts, strict=True):
            f = fmt[0] if isinstance(fmt, list) else fmt
            px = np.frombuffer(bytes(buf[0] if isinstance(buf, list) and buf and isinstance(buf[0], list) else buf),
                               dtype=np.uint8)  # fmt: skip
            out.append((float(ti), px.reshape(f["height"], f["width"], -1)))
        t_enc, blobs = self.column(entity, "EncodedImage:blob", timeline)
        for ti, blob in zip(t_enc, blobs, strict=True):
            data = bytes(blob[0] if isinstance(blob, list) and blob and isinstance(blob[0], list) else blob)
            out.append((float(ti), decode_png(data)))
        out.sort(key=lambda r: r[0])
        return np.array([ti for ti, _ in out]), [im for _, im in out]

    def vectors(self, entity: str, component: str, timeline: str = TIMELINE) -> tuple[np.ndarray, np.ndarray]:
        """A per-row 3-vector component (e.g. ``"Transform3D:translation"``): t (N,), (N, 3).

        For batch components (e.g. ``"Points3D:positions"``) the first instance of each row."""
        t, vals = self.column(entity, component, timeline)
        rows = [np.asarray(v[0] if v and isinstance(v[0], (list, tuple)) else v, dtype=float) for v in vals]
        return t, (np.vstack(rows) if rows else np.zeros((0, 3)))


    # ------------------------------------------------------------------ documents and properties
    def texts(self, entity: str, component: str = "TextLog:text") -> list[tuple[float, str]]:
        """(t [s], text) of a text log (or, with ``component="TextDocument:text"``, a document; t NaN if static)."""
        t, vals = self.column(entity, component)
        return [(float(ti), str(v[0] if isinstance(v, list) else v)) for ti, v in zip(t, vals, strict=True)]

    def document(self, entity: str) -> str | None:
        """The latest text of a TextDocument entity (e.g. ``summary``, ``missing/chem``), or None."""
        docs = self.texts(entity, "TextDocument:text")
        return docs[-1][1] if docs else None

    def states(self, entity: str) -> list[tuple[float, str]]:
        """(t [s], state) of a StateChange entity (``phases/mission``, ``phases/strategy``, ``phases/mode``)."""
        return self.texts(entity, "StateChange:state")

    def property_value(self, name: str, field: str) -> Any:
        """One field of a recording property (e.g. ``("result", "error_m")``), or None."""
        _, vals = self.column(f"__properties/{name}", field)
        if not vals:
            return None
        v = vals[-1]
        return v[0] if isinstance(v, list) and len(v) == 1 else v

    def summary(self) -> RunSummary | None:
        """The run summary the recording carries (property ``result``), or None."""
        text = self.property_value("result", "json")
        return RunSummary.from_json(text) if text else None

    def layout(self) -> Layout | None:
        """The layout facts of the final blueprint (property ``layout``), or None."""
        text = self.property_value("layout", "json")
        return Layout.from_json(text) if text else None

    def _blueprint_values(self, component: str) -> list[Any]:
        """Every value of one blueprint component (e.g. ``"TimeAxis:view_range"``) in the final blueprint."""
        final = self._final_blueprint()
        out: list[Any] = []
        for c in self._reader.stream(store=final).to_chunks() if final is not None else []:
            rb = c.to_record_batch()
            if component in rb.schema.names:
                out += [v[0] if isinstance(v, list) and v else v for v in rb.column(component).to_pylist()]
        return out

    def blueprint_time_ranges(self) -> list[tuple[float, float]]:
        """(start, end) [s] of the time axes the final blueprint opens its plots on."""
        return [(_boundary_s(r["start"]), _boundary_s(r["end"])) for r in self._blueprint_values("TimeAxis:view_range")
                if isinstance(r, dict) and "start" in r and "end" in r]  # fmt: skip

    def blueprint_value_ranges(self) -> list[tuple[float, float]]:
        """(low, high) of the value axes the final blueprint fixes."""
        return [(float(r[0]), float(r[1])) for r in self._blueprint_values("ScalarAxis:range") if r is not None]


def _boundary_s(b: Any) -> float:
    """A time range boundary as decoded from arrow (nanoseconds) -> seconds (NaN if not a time)."""
    if isinstance(b, (int, float)) and not isinstance(b, bool):
        return float(b) * 1e-9
    if isinstance(b, dict):
        for v in b.values():
            got = _boundary_s(v)
            if got == got:
                return got
    return float("nan")


def list_entity_paths(path: Path | str) -> list[str]:
    """Entity paths of a ``.rrd`` file (see :meth:`RrdLog.entity_paths`)."""
    return RrdLog(path).entity_paths()


def read_scalars(path: Path | str, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """Scalar series of one entity of a ``.rrd`` file: t [s], values (see :meth:`RrdLog.scalars`)."""
    return RrdLog(path).scalars(entity)


__all__ = ["SCALARS", "RrdLog", "list_entity_paths", "read_scalars"]
