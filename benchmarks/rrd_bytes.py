"""Where the bytes of a ``.rrd`` file go: per store, static or temporal, per entity, per column, and the footer.

``rerun.chunk.RrdReader`` gives a file's chunks but not what each costs on disk, so this reads the
file's messages itself (the RRF2 stream of Rerun 0.41: a 12-byte header, then messages of a
16-byte header ``(kind, length)`` and a protobuf body; kind 1 sets a store's info, 2 is an
Arrow message holding one chunk as LZ4-compressed Arrow IPC, 3 activates a blueprint, 0 ends the
stream and carries the footer: per store the Arrow schema of all its columns and a table with a
row per chunk, the manifest for random access; a 32-byte trailer follows). For every chunk: its
store (recording or blueprint), entity path, static or temporal, rows and size on disk; the size
is split between the chunk's schema, its row ids, its time columns and its data columns by
compressing each alone with LZ4 (an estimate: the file compresses the whole message at once).

    python benchmarks/rrd_bytes.py FILE.rrd [FILE.rrd ...] [--top 20]
"""

from __future__ import annotations

import argparse
import struct
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

HEADER = 12  # b"RRF2", the SDK's version (4 bytes), the encoding options (4 bytes)
ROW_ID = "rerun.controls.RowId"


def _varint(b: bytes, i: int) -> tuple[int, int]:
    out = shift = 0
    while True:
        x = b[i]
        i += 1
        out |= (x & 0x7F) << shift
        shift += 7
        if x < 0x80:
            return out, i


def proto_fields(b: bytes) -> list[tuple[int, int | bytes]]:
    """The (field number, value) pairs of a protobuf message: ints for varints, bytes otherwise."""
    i, out = 0, []
    while i < len(b):
        key, i = _varint(b, i)
        wire = key & 7
        v: int | bytes
        if wire == 0:
            v, i = _varint(b, i)
        elif wire == 2:
            n, i = _varint(b, i)
            v, i = b[i : i + n], i + n
        elif wire in (1, 5):
            n = 8 if wire == 1 else 4
            v, i = b[i : i + n], i + n
        else:
            raise ValueError(f"protobuf wire type {wire}")
        out.append((key >> 3, v))
    return out


def messages(data: bytes) -> Iterator[tuple[int, bytes, int]]:
    """(kind, body, bytes on disk with the message header) of every message; kind -1 is the trailer."""
    i = HEADER
    while i < len(data):
        kind, n = struct.unpack_from("<QQ", data, i)
        yield kind, data[i + 16 : i + 16 + n], 16 + n
        i += 16 + n
        if kind == 0:
            if i < len(data):
                yield -1, b"", len(data) - i
            return


@dataclass
class ChunkCost:
    """One chunk: where it is and what its bytes on disk are (``parts``: estimated split by column kind)."""

    store: str
    entity: str
    static: bool
    rows: int
    bytes: int
    parts: dict[str, int]


def _lz4(b: bytes) -> int:
    return len(pa.compress(b, codec="lz4_raw", asbytes=True)) if b else 0


def _ipc(table: pa.Table | None, schema: pa.Schema) -> bytes:
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, schema) as w:
        if table is not None:
            w.write_table(table)
    return bytes(sink.getvalue())


def chunk_cost(body: bytes, size: int) -> ChunkCost:
    """A chunk's :class:`ChunkCost` from its Arrow message's body (``size``: its bytes on disk)."""
    f = dict(proto_fields(body))
    store = dict(proto_fields(f[1]))  # type: ignore[arg-type]
    payload = f[5]
    assert isinstance(payload, bytes)
    if f.get(2) == 2:  # LZ4
        payload = pa.decompress(payload, f[3], codec="lz4_raw", asbytes=True)
    reader = pa.ipc.open_stream(pa.py_buffer(payload))
    table = reader.read_all()
    meta = reader.schema.metadata or {}
    parts: Counter[str] = Counter({"schema": _lz4(_ipc(None, reader.schema))})
    for field, col in zip(table.schema, table.columns, strict=True):
        role = (field.metadata or {}).get(b"rerun:kind", b"")
        kind = "row ids" if field.name == ROW_ID else "time" if role == b"index" else "data"
        raw = b"".join(buf.to_pybytes() for c in col.chunks for buf in c.buffers() if buf is not None)
        parts[kind] += _lz4(raw)
    est = sum(parts.values()) or 1
    scaled = {k: round(v * size / est) for k, v in parts.items()}  # the estimate, scaled to the real size
    return ChunkCost(store="blueprint" if store.get(1) == 2 else "recording",
                     entity=meta.get(b"rerun:entity_path", b"?").decode(), static=bool(f.get(7)),
                     rows=table.num_rows, bytes=size, parts=scaled)  # fmt: skip


def footer_parts(body: bytes) -> dict[str, int]:
    """The footer's bytes per store: its columns' schema and its per-chunk table (the manifest)."""
    out: Counter[str] = Counter()
    for _, entry in proto_fields(body):
        assert isinstance(entry, bytes)
        fields = proto_fields(entry)
        store = dict(proto_fields(fields[0][1]))  # type: ignore[arg-type]
        name = "blueprint" if store.get(1) == 2 else "recording"
        for num, v in fields[1:]:
            if isinstance(v, bytes):
                out[f"footer: {name} {'schema' if num == 2 else 'chunk table' if num == 4 else 'other'}"] += len(v)
    return dict(out)


def breakdown(path: Path) -> tuple[int, list[ChunkCost], dict[str, int]]:
    """(file size, every chunk's cost, the other bytes by kind: footer parts, store infos, trailer)."""
    data = path.read_bytes()
    chunks: list[ChunkCost] = []
    other: Counter[str] = Counter({"stream header": HEADER})
    for kind, body, size in messages(data):
        if kind == 2:
            chunks.append(chunk_cost(body, size))
        elif kind == 0:
            parts = footer_parts(body)
            other.update(parts)
            other["footer: headers"] += size - sum(parts.values())
        else:
            other[{1: "store infos", 3: "blueprint activation", -1: "trailer"}.get(kind, f"kind {kind}")] += size
    return len(data), chunks, dict(other)


def report(path: Path, top: int = 20) -> None:
    """Print the breakdown of one file."""
    size, chunks, other = breakdown(path)
    pct = 100.0 / size
    print(f"{path}: {size:,} bytes, {len(chunks)} chunks")
    groups: Counter[str] = Counter()
    counts: Counter[str] = Counter()
    parts: Counter[str] = Counter()
    for c in chunks:
        key = f"{c.store} {'static' if c.static else 'temporal'}"
        groups[key] += c.bytes
        counts[key] += 1
        for k, v in c.parts.items():
            parts[f"{key}: {k}"] += v
    for key, b in groups.most_common():
        print(f"  {key:28s} {b:9,d} B {b * pct:5.1f} %  {counts[key]:4d} chunks")
    for key, b in sorted(other.items(), key=lambda kv: -kv[1]):
        print(f"  {key:28s} {b:9,d} B {b * pct:5.1f} %")
    print("  by column kind (estimated):")
    for key, b in parts.most_common():
        print(f"    {key:36s} {b:9,d} B {b * pct:5.1f} %")
    print(f"  top {top} entities:")
    ent: Counter[tuple[str, str]] = Counter()
    per: Counter[tuple[str, str]] = Counter()
    for c in chunks:
        ek = (f"{c.store[0]}{'S' if c.static else 'T'}", c.entity)
        ent[ek] += c.bytes
        per[ek] += 1
    for (kind, e), b in ent.most_common(top):
        print(f"    {kind} {e:44s} {b:9,d} B  {per[(kind, e)]} chunk(s)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--top", type=int, default=20, help="entities listed, largest first")
    a = ap.parse_args()
    for p in a.files:
        report(p, a.top)


if __name__ == "__main__":
    main()
