"""MAVLink FTP (FILE_TRANSFER_PROTOCOL) server, answering as PX4's ``mavlink_ftp.cpp`` does.

Ground stations try FTP first: MAVProxy opens ``@PARAM/param.pck`` to download the parameters
and only falls back to PARAM_REQUEST_LIST when the open is refused; QGroundControl's FTPManager
lists directories and fetches component metadata. Without an answer MAVProxy waited out eleven
retries (12-14 s) before its fallback. PX4 serves its SD card; ``@PARAM/param.pck`` is ArduPilot's
virtual file and PX4 answers its open with a NAK ``FileNotFound`` at once, which is what this
server does for any path it does not hold.

The file system is read-only and in memory (``files``: path -> bytes, empty by default, as a
vehicle without an SD card). Supported: None, TerminateSession, ResetSessions, ListDirectory,
OpenFileRO, ReadFile, BurstReadFile, CalcFileCRC32 (zlib's CRC-32, PX4's ``crc32part``). Every
write operation is refused with ``FailFileProtected``; an unknown opcode (e.g. MAVProxy's
ListDirectoryWithTime) with ``UnknownCommand``, as PX4. One session (id 0), as PX4. A repeated
request (same sequence number) gets the last small reply again, as PX4 does. Payload layout
(``PayloadHeader``): seq u16, session u8, opcode u8, size u8, req_opcode u8, burst_complete u8,
padding u8, offset u32, data[239].
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import Any

from sitl.link.endpoint import COMPONENT_ID, SYSTEM_ID, Endpoint, Link
from wire.dialect import mavlink as mav

HEADER = struct.Struct("<HBBBBBBI")
MAX_DATA = 239  # 251-byte payload minus the 12-byte header

# Opcodes (PX4 MavlinkFTP::Opcode).
NONE, TERMINATE, RESET, LIST, OPEN_RO, READ, CREATE, WRITE, REMOVE, MKDIR, RMDIR, OPEN_WO, TRUNCATE, RENAME, \
    CRC32, BURST = range(16)  # fmt: skip
ACK, NAK = 128, 129
WRITE_OPS = {CREATE, WRITE, REMOVE, MKDIR, RMDIR, OPEN_WO, TRUNCATE, RENAME}
# Error codes (PX4 MavlinkFTP::ErrorCode).
ERR_FAIL, ERR_FAIL_ERRNO, ERR_INVALID_DATA_SIZE, ERR_INVALID_SESSION, ERR_NO_SESSIONS, ERR_EOF, \
    ERR_UNKNOWN_COMMAND, ERR_FILE_EXISTS, ERR_FILE_PROTECTED, ERR_FILE_NOT_FOUND = range(1, 11)  # fmt: skip
DIRENT_FILE, DIRENT_DIR = ord("F"), ord("D")


@dataclass
class Op:
    """One decoded FTP payload."""

    seq: int
    session: int
    opcode: int
    size: int
    req_opcode: int
    burst_complete: int
    offset: int
    data: bytes

    @classmethod
    def parse(cls, payload: list[int] | bytes) -> Op:
        raw = bytes(payload).ljust(HEADER.size + MAX_DATA, b"\0")
        seq, session, opcode, size, req, burst, _pad, offset = HEADER.unpack_from(raw)
        return cls(seq, session, opcode, size, req, burst, offset, raw[HEADER.size:HEADER.size + min(size, MAX_DATA)])

    def pack(self) -> list[int]:
        head = HEADER.pack(self.seq & 0xFFFF, self.session, self.opcode, self.size, self.req_opcode,
                           self.burst_complete, 0, self.offset)  # fmt: skip
        return list((head + self.data[:self.size]).ljust(HEADER.size + MAX_DATA, b"\0"))

    def path(self) -> str:
        return self.data.split(b"\0", 1)[0].decode("utf-8", "replace")


class FtpServer:
    """FILE_TRANSFER_PROTOCOL handler on an endpoint, over a read-only in-memory file tree."""

    def __init__(self, ep: Endpoint, files: dict[str, bytes] | None = None) -> None:
        self.ep = ep
        self.files = {_norm(k): bytes(v) for k, v in (files or {}).items()}
        self.open_path: str | None = None
        self._last: tuple[Any, int] | None = None  # (reply message, its seq) for a repeated request
        ep.handlers["FILE_TRANSFER_PROTOCOL"] = self.on_message

    def on_message(self, msg: Any, link: Link) -> None:
        if msg.target_system not in (0, SYSTEM_ID) or msg.target_component not in (0, COMPONENT_ID):
            return
        op = Op.parse(msg.payload)
        self.ep.counters["ftp_requests"] += 1
        if self._last is not None and op.seq + 1 == self._last[1]:
            self.ep.reply(self._last[0], link)  # our answer was lost: the same answer again
            return
        replies = [self._nak(op, ERR_INVALID_DATA_SIZE)] if op.size > MAX_DATA else self._work(op)
        out = [mav.MAVLink_file_transfer_protocol_message(0, msg.get_srcSystem(), msg.get_srcComponent(), r.pack())
               for r in replies]  # fmt: skip
        self._last = (out[-1], replies[-1].seq) if len(replies) == 1 and replies[0].size <= 4 else None
        if any(r.opcode == NAK for r in replies):
            self.ep.counters["ftp_naks"] += 1
        self.ep.reply_many(out, link)

    # ------------------------------------------------------------------ operations
    def _work(self, op: Op) -> list[Op]:
        code = op.opcode
        if code == NONE:
            return [self._ack(op, b"")]
        if code == TERMINATE:
            if op.session != 0 or self.open_path is None:
                return [self._nak(op, ERR_INVALID_SESSION)]
            self.open_path = None
            return [self._ack(op, b"")]
        if code == RESET:
            self.open_path = None
            return [self._ack(op, b"")]
        if code == LIST:
            return [self._list(op)]
        if code == OPEN_RO:
            if self.open_path is not None:
                return [self._nak(op, ERR_NO_SESSIONS)]
            path = _norm(op.path())
            if path not in self.files:
                return [self._nak(op, ERR_FILE_NOT_FOUND)]
            self.open_path = path
            return [self._ack(op, struct.pack("<I", len(self.files[path])), session=0)]
        if code in (READ, BURST):
            return self._read(op, burst=code == BURST)
        if code == CRC32:
            path = _norm(op.path())
            if path not in self.files:
                return [self._nak(op, ERR_FILE_NOT_FOUND)]
            return [self._ack(op, struct.pack("<I", zlib.crc32(self.files[path]) & 0xFFFFFFFF))]
        if code in WRITE_OPS:
            return [self._nak(op, ERR_FILE_PROTECTED)]
        return [self._nak(op, ERR_UNKNOWN_COMMAND)]

    def _list(self, op: Op) -> Op:
        d = _norm(op.path()).rstrip("/") + "/"
        entries: list[bytes] = []
        dirs: set[str] = set()
        for path in sorted(self.files):
            if not path.startswith(d) or path == d:
                continue
            rest = path[len(d):]
            if "/" in rest:
                sub = rest.split("/", 1)[0]
                if sub not in dirs:
                    dirs.add(sub)
                    entries.append(bytes([DIRENT_DIR]) + sub.encode() + b"\0")
            else:
                entries.append(bytes([DIRENT_FILE]) + f"{rest}\t{len(self.files[path])}".encode() + b"\0")
        if d != "/" and not entries:
            return self._nak(op, ERR_FILE_NOT_FOUND)
        data = b""
        for e in entries[op.offset:]:
            if len(data) + len(e) > MAX_DATA:
                break
            data += e
        return self._ack(op, data) if data else self._nak(op, ERR_EOF)

    def _read(self, op: Op, burst: bool) -> list[Op]:
        if op.session != 0 or self.open_path is None:
            return [self._nak(op, ERR_INVALID_SESSION)]
        content = self.files[self.open_path]
        if op.offset >= len(content):
            return [self._nak(op, ERR_EOF)]
        if not burst:
            n = min(op.size or MAX_DATA, MAX_DATA)
            return [self._ack(op, content[op.offset:op.offset + n])]
        # A burst streams the rest of the file, one ACK per chunk, the last marked complete.
        out = []
        for k, ofs in enumerate(range(op.offset, len(content), MAX_DATA)):
            chunk = self._ack(op, content[ofs:ofs + MAX_DATA])
            chunk.seq, chunk.offset = op.seq + 1 + k, ofs
            chunk.burst_complete = int(ofs + MAX_DATA >= len(content))
            out.append(chunk)
        return out

    @staticmethod
    def _ack(op: Op, data: bytes, session: int | None = None) -> Op:
        return Op(op.seq + 1, op.session if session is None else session, ACK, len(data), op.opcode, 0, op.offset,
                  data)  # fmt: skip

    @staticmethod
    def _nak(op: Op, err: int) -> Op:
        return Op(op.seq + 1, op.session, NAK, 1, op.opcode, 0, op.offset, bytes([err]))


def _norm(path: str) -> str:
    """A path as the tree keys it: leading slash, no trailing slash (root is "/")."""
    p = "/" + path.strip().lstrip("/")
    return p.rstrip("/") or "/"
