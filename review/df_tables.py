"""ArduPilot DataFlash binary logs as numpy tables, read through pymavlink's ``DFReader_binary``.

pymavlink's reader memory-maps the file and indexes it (its compiled ``dfindexer``): the offset of
every message, per type, and each type's FMT definition. Decoding message by message through
``recv_match`` costs tens of microseconds each in Python; here a whole type is decoded at once
instead: its payloads are gathered from the memory map at the indexed offsets and viewed as a numpy
structured array built from the same FMT definition, with pymavlink's per-format multipliers
(``FORMAT_TO_STRUCT``: centi-units, 1e-7 degrees) applied. Strings stay bytes until asked for.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.DFReader import FORMAT_TO_STRUCT, DFReader_binary

#: struct codes of FORMAT_TO_STRUCT -> numpy little-endian dtypes.
_NP = {"b": "i1", "B": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4", "q": "<i8", "Q": "<u8",
       "f": "<f4", "d": "<f8", "e": "<f2"}  # fmt: skip
HEADER_BYTES = 3  # HEAD1, HEAD2, message type
HEAD = b"\xa3\x95"  # HEAD1, HEAD2 of every DataFlash message


def _dtype(fmt: Any) -> tuple[np.dtype, list[float | None]] | None:
    """numpy dtype of one FMT definition's payload, and its multipliers (None for an unknown code)."""
    fields, mults = [], []
    for col, c in zip(fmt.columns, fmt.msg_fmts, strict=False):
        code, mult, _ = FORMAT_TO_STRUCT[c]
        if code.endswith("s"):
            fields.append((col, f"S{code[:-1]}"))
        elif code in _NP:
            fields.append((col, _NP[code]))
        else:
            return None
        mults.append(mult)
    try:
        return np.dtype(fields), mults
    except (TypeError, ValueError):  # duplicate or empty column names
        return None


class DataFlashTables:
    """Typed access to the messages of a DataFlash ``.bin``: ``tables.get("IMU")`` -> {column: array}.

    ``printed`` holds what pymavlink printed while indexing (its warnings about bad bytes and formats,
    on stdout and stderr).
    """

    def __init__(self, path: Path) -> None:
        out = io.StringIO()
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
                self.reader = DFReader_binary(str(path), zero_time_base=False)
        except Exception as e:  # pymavlink raises plain exceptions on a damaged index
            raise ValueError(f"{path}: not a readable DataFlash log ({e})") from e
        self.printed = [line.strip() for line in out.getvalue().splitlines() if line.strip()]
        self._buf = np.frombuffer(self.reader.data_map, dtype=np.uint8)
        self._cache: dict[str, dict[str, np.ndarray] | None] = {}
        self.undecodable: list[str] = []

    def counts(self) -> dict[str, int]:
        """Messages per type name."""
        r = self.reader
        return {f.name: len(r.offsets[tid]) for tid, f in r.formats.items()
                if tid < len(r.offsets) and len(r.offsets[tid])}  # fmt: skip

    def cut_off(self) -> bool:
        """True when the file ends inside a message: pymavlink indexes a message whose payload runs past
        the end of the file (its FMT length), or the bytes after the last message start a header."""
        r, size = self.reader, len(self._buf)
        ends = [int(offs[-1]) + r.formats[tid].len for tid, offs in enumerate(r.offsets)
                if len(offs) and tid in r.formats]  # fmt: skip
        end = max(ends, default=0)
        tail = bytes(self._buf[end:end + 2])
        return end > size or (len(tail) > 0 and HEAD.startswith(tail))

    def get(self, name: str) -> dict[str, np.ndarray] | None:
        """All messages of one type as columns (multipliers applied; numbers as float), or None."""
        if name not in self._cache:
            self._cache[name] = self._decode(name)
        return self._cache[name]

    def _decode(self, name: str) -> dict[str, np.ndarray] | None:
        r = self.reader
        tid = r.name_to_id.get(name)
        if tid is None or tid >= len(r.offsets) or not len(r.offsets[tid]):
            return None
        spec = _dtype(r.formats[tid])
        if spec is None or spec[0].itemsize != r.formats[tid].len - HEADER_BYTES:
            self.undecodable.append(name)
            return None
        dt, mults = spec
        ofs = np.asarray(r.offsets[tid], dtype=np.int64) + HEADER_BYTES
        ofs = ofs[ofs + dt.itemsize <= len(self._buf)]
        raw = self._buf[ofs[:, None] + np.arange(dt.itemsize)]
        rec = raw.view(dt).reshape(-1)
        out: dict[str, np.ndarray] = {}
        for col, mult in zip(dt.names or (), mults, strict=True):
            a = rec[col]
            if a.dtype.kind == "S":
                out[col] = a
            else:
                out[col] = a.astype(float) * mult if mult is not None else a.astype(float)
        return out

    def time_s(self, table: dict[str, np.ndarray]) -> np.ndarray:
        """Boot time [s] of a table's rows (TimeUS, or TimeMS in old logs)."""
        if "TimeUS" in table:
            return table["TimeUS"] * 1e-6
        return table.get("TimeMS", np.full(len(next(iter(table.values()))), np.nan)) * 1e-3

    def first_instance(self, name: str, column: str) -> dict[str, np.ndarray] | None:
        """Rows of instance 0 (``column`` = "I", "C", "Instance", ...) when the type has that column."""
        t = self.get(name)
        if t is None or column not in t:
            return t
        keep = t[column] == 0
        return {k: v[keep] for k, v in t.items()}

    def texts(self, table: dict[str, np.ndarray], column: str) -> list[str]:
        return [b.split(b"\0", 1)[0].decode("utf-8", "replace") for b in table[column]]


__all__ = ["DataFlashTables"]
