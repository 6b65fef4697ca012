"""A session file's chunks, read out of a read-only memory map: their records (decompressed, each
chunk's CRC checked) and their message indexes, with errors that say where the chunk lies."""

from __future__ import annotations

import mmap
from pathlib import Path
from typing import BinaryIO

import numpy as np

from teleprev.errors import SessionError
from teleprev.session import records as mr


class ChunkFile:
    def __init__(self, f: BinaryIO, path: Path, start_ns: int | None, *, verify_crc: bool):
        """`f` is the open session file (closed by close()); `start_ns` is the session's first log time,
        from which errors give a chunk's place in time."""
        self.f = f
        self.path = path
        self.start_ns = start_ns
        self.verify_crc = verify_crc
        self.mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)  # chunks are read without copies

    def describe(self, chunk: mr.ChunkIndex) -> str:
        """Where a chunk is, in the words a user needs: its log times from the session's start."""
        t0 = self.start_ns or 0
        return (f"at byte {chunk.offset}, log time {(chunk.start_ns - t0) / 1e9:.3f}-"
                f"{(chunk.end_ns - t0) / 1e9:.3f} s into the session")

    def records(self, chunk: mr.ChunkIndex) -> bytes:
        """The chunk's records; a chunk that does not read back whole is a SessionError naming it."""
        try:
            return self.read(chunk)
        except mr.McapFormatError as exc:
            raise SessionError(f"the chunk {self.describe(chunk)} is damaged ({exc}); "
                               f"`teleprev recover {self.path}` keeps everything else", str(self.path)) from None

    def read(self, chunk: mr.ChunkIndex) -> bytes:
        """The chunk's records; raises McapFormatError when it does not read back whole."""
        body = parsed = None
        try:
            body = mr.record_at(self.mm, chunk.offset, mr.CHUNK)
            parsed = mr.parse_chunk(body, 0, len(body))
            return mr.decompress(parsed, check_crc=self.verify_crc)
        finally:  # views into the mapping must go before close() can unmap it
            if parsed is not None and isinstance(parsed.data, memoryview):
                parsed.data.release()
            if body is not None:
                body.release()

    def iter_records(self, chunk: mr.ChunkIndex, buf: bytes):
        """(opcode, body start, body end) of each record of the chunk's records `buf`."""
        try:
            for op, b, e in mr.iter_records(buf):
                if op == mr.MESSAGE and e - b < 22:
                    raise mr.McapFormatError("message record too short", b - 9)
                yield op, b, e
        except mr.McapFormatError as exc:
            raise SessionError(f"chunk at byte {chunk.offset} holds a malformed record: {exc}",
                               str(self.path)) from None

    def message_times(self, chunk: mr.ChunkIndex) -> list[tuple[int, int]]:
        """(channel, log_time) of every message in the chunk, in file order."""
        buf = self.records(chunk)
        head = mr.MESSAGE_HEADER.unpack_from
        return [head(buf, b)[0:3:2] for op, b, e in self.iter_records(chunk, buf) if op == mr.MESSAGE]

    def message_index(self, chunk: mr.ChunkIndex) -> dict[int, np.ndarray] | None:
        """The chunk's message indexes: channel -> (n, 2) uint64 [log_time, record offset in the
        chunk], or None when the file has none for this chunk."""
        if not (chunk.message_index_length and chunk.message_index_offsets):
            return None
        start = min(chunk.message_index_offsets.values())
        out = {}
        try:
            block = mr.read_exact(self.f, start, chunk.message_index_length)
            for op, b, e in mr.iter_records(block):
                if op == mr.MESSAGE_INDEX:
                    ch, entries = mr.parse_message_index(block[b:e])
                    out[ch] = entries
        except mr.McapFormatError as exc:
            raise SessionError(f"message index of the chunk at byte {chunk.offset} is damaged: {exc}",
                               str(self.path)) from None
        return out

    def release_pages(self) -> None:
        """Drop the file's pages from this process's resident set (they stay in the kernel's page cache).

        The whole file is memory-mapped, so every page read would otherwise stay resident until the
        reader closes and the process would grow with the session's length; messages() calls this every
        few chunks, so long sessions read in flat memory."""
        if hasattr(mmap, "MADV_DONTNEED"):
            try:
                self.mm.madvise(mmap.MADV_DONTNEED)
            except (OSError, ValueError):  # closed, or refused: only memory accounting is at stake
                pass

    def close(self) -> None:
        try:
            self.mm.close()
        except BufferError:  # a view still held by an error on its way up: unmapped when that goes
            pass
        self.f.close()
