"""Test helper: a minimal PX4 ULog writer (used by test_review.py and the identification's log tests)."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any


class UlogWriter:
    """Minimal ULog writer (PX4 "ULog File Format", version 1), enough for pyulog to read back.

    Header: magic ``ULog\\x01\\x12\\x35``, version byte, start timestamp (uint64 us). Then
    messages ``<uint16 size><uint8 type><payload>``: ``B`` flag bits (40 bytes, all zero),
    ``F`` formats ``name:type field;type[n] field;...``, ``I`` info ``<uint8 key len>"type
    key"<value>``, ``A`` subscriptions ``<uint8 multi_id><uint16 msg_id>name``, ``D`` data
    ``<uint16 msg_id><fields packed little-endian in format order>``, ``L`` logging
    ``<uint8 level><uint64 timestamp>text``. Every format starts with ``uint64_t timestamp``.
    """

    TYPES = {"uint64_t": "Q", "int32_t": "i", "uint32_t": "I", "uint16_t": "H", "uint8_t": "B", "float": "f",
             "bool": "?", "char": "c", "int8_t": "b"}  # fmt: skip

    def __init__(self, path: Path, t0_us: int = 0) -> None:
        self.f = path.open("wb")
        self.f.write(b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", t0_us))
        self._msg("B", bytes(40))
        self.formats: dict[str, list[tuple[str, int, str]]] = {}
        self.ids: dict[str, int] = {}

    def _msg(self, kind: str, payload: bytes) -> None:
        self.f.write(struct.pack("<HB", len(payload), ord(kind)) + payload)

    def info(self, key: str, value: str) -> None:
        k = f"char[{len(value)}] {key}".encode()
        self._msg("I", bytes([len(k)]) + k + value.encode())

    def format(self, name: str, fields: list[tuple[str, int, str]]) -> None:
        """fields: (type, array length or 0, name); nested types by their format name."""
        self.formats[name] = fields
        text = "".join(f"{t}[{n}] {f};" if n else f"{t} {f};" for t, n, f in fields)
        self._msg("F", f"{name}:{text}".encode())

    def subscribe(self, name: str) -> None:
        self.ids[name] = len(self.ids)
        self._msg("A", struct.pack("<BH", 0, self.ids[name]) + name.encode())

    def _pack(self, name: str, values: dict[str, Any]) -> bytes:
        out = b""
        for t, n, f in self.formats[name]:
            v = values.get(f, [0] * n if n else 0)
            items = (list(v) + [0] * n)[:n] if n else [v]  # arrays padded with zeros to their length
            for x in items:
                if t in self.TYPES:
                    out += struct.pack("<" + self.TYPES[t], x)
                else:
                    out += self._pack(t, x if isinstance(x, dict) else {})
        return out

    def data(self, name: str, values: dict[str, Any]) -> None:
        self._msg("D", struct.pack("<H", self.ids[name]) + self._pack(name, values))

    def log(self, t_us: int, text: str, level: str = "6") -> None:
        self._msg("L", struct.pack("<BQ", ord(level), t_us) + text.encode())

    def close(self) -> None:
        self.f.close()
