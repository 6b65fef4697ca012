"""Strict, low-level reading of MCAP records (https://mcap.dev/spec) for the session reader and recover.

The mcap library reads messages through many small reads and tolerates short reads; the reader needs
speed (whole chunks parsed with struct.unpack_from) and recover needs to know exactly where the data
stops making sense, so both use this module. Every parse checks bounds and raises McapFormatError.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field

from isal.isal_zlib import crc32  # zlib's CRC-32, several times faster: eval checks every chunk it reads

MAGIC = b"\x89MCAP0\r\n"

HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = range(0x01, 0x09)
ATTACHMENT, ATTACHMENT_INDEX, STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = range(0x09, 0x10)
KNOWN_OPCODES = frozenset(range(0x01, 0x10))
FOOTER_RECORD_SIZE = 9 + 20  # opcode + length + summary_start + summary_offset_start + crc

_OP_LEN = struct.Struct("<BQ")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
MESSAGE_HEADER = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time


class McapFormatError(ValueError):
    """A record that does not parse; `offset` is where in the file (or chunk) it starts, when known."""

    def __init__(self, message: str, offset: int | None = None):
        super().__init__(message if offset is None else f"{message} (at byte {offset})")
        self.offset = offset


@dataclass(slots=True)
class SchemaRecord:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(slots=True)
class ChannelRecord:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


@dataclass(slots=True)
class ChunkRecord:
    start_ns: int
    end_ns: int
    uncompressed_size: int
    crc: int
    compression: str
    data: bytes | memoryview  # compressed records


@dataclass(slots=True)
class ChunkIndex:
    start_ns: int
    end_ns: int
    offset: int
    length: int
    message_index_offsets: dict[int, int]
    message_index_length: int
    compression: str


@dataclass(slots=True)
class Statistics:
    message_count: int
    schema_count: int
    channel_count: int
    attachment_count: int
    metadata_count: int
    chunk_count: int
    start_ns: int
    end_ns: int
    channel_message_counts: dict[int, int]


@dataclass(slots=True)
class AttachmentRecord:
    log_time: int
    create_time: int
    name: str
    media_type: str
    data: bytes


@dataclass
class SummarySection:
    schemas: dict[int, SchemaRecord] = field(default_factory=dict)
    channels: dict[int, ChannelRecord] = field(default_factory=dict)
    chunks: list[ChunkIndex] = field(default_factory=list)
    statistics: Statistics | None = None
    metadata: list[tuple[str, int, int]] = field(default_factory=list)  # name, offset, length


class _Cursor:
    """Bounds-checked sequential reads from buf[pos:end]."""

    __slots__ = ("buf", "pos", "end")

    def __init__(self, buf, pos: int = 0, end: int | None = None):
        self.buf, self.pos, self.end = buf, pos, len(buf) if end is None else end

    def _take(self, n: int) -> int:
        p = self.pos
        if n < 0 or p + n > self.end:
            raise McapFormatError(f"record field runs past its record ({n} bytes wanted, {self.end - p} left)")
        self.pos = p + n
        return p

    def u8(self) -> int:
        return self.buf[self._take(1)]

    def u16(self) -> int:
        return _U16.unpack_from(self.buf, self._take(2))[0]

    def u32(self) -> int:
        return _U32.unpack_from(self.buf, self._take(4))[0]

    def u64(self) -> int:
        return _U64.unpack_from(self.buf, self._take(8))[0]

    def raw(self, n: int) -> bytes:
        p = self._take(n)
        return bytes(self.buf[p:p + n])

    def string(self) -> str:
        try:
            return self.raw(self.u32()).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise McapFormatError(f"string is not UTF-8: {exc}") from None

    def str_map(self) -> dict[str, str]:
        n = self.u32()
        sub = _Cursor(self.buf, self._take(n), self.pos)
        out = {}
        while sub.pos < sub.end:
            k = sub.string()
            out[k] = sub.string()
        return out

    def view(self, n: int) -> memoryview:
        p = self._take(n)
        return memoryview(self.buf)[p:p + n]

    def rest(self) -> bytes:
        p = self._take(self.end - self.pos)
        return bytes(self.buf[p:self.end])


def parse_schema(buf, pos: int, end: int) -> SchemaRecord:
    c = _Cursor(buf, pos, end)
    return SchemaRecord(c.u16(), c.string(), c.string(), c.raw(c.u32()))


def parse_channel(buf, pos: int, end: int) -> ChannelRecord:
    c = _Cursor(buf, pos, end)
    return ChannelRecord(c.u16(), c.u16(), c.string(), c.string(), c.str_map())


def parse_metadata(buf, pos: int, end: int) -> tuple[str, dict[str, str]]:
    c = _Cursor(buf, pos, end)
    return c.string(), c.str_map()


def parse_chunk(buf, pos: int, end: int) -> ChunkRecord:
    """A chunk record; its data is a view into `buf` (no copy)."""
    c = _Cursor(buf, pos, end)
    start, stop, usize, crc = c.u64(), c.u64(), c.u64(), c.u32()
    compression = c.string()
    return ChunkRecord(start, stop, usize, crc, compression, c.view(c.u64()))


def parse_attachment(buf, pos: int, end: int) -> AttachmentRecord:
    c = _Cursor(buf, pos, end)
    log_time, create_time = c.u64(), c.u64()
    name, media_type = c.string(), c.string()
    data = c.raw(c.u64())
    covered = c.pos  # the CRC covers every field before it
    crc = c.u32()
    if crc and crc32(buf[pos:covered]) != crc:
        raise McapFormatError("attachment CRC mismatch")
    return AttachmentRecord(log_time, create_time, name, media_type, data)


def decompress(chunk: ChunkRecord, *, check_crc: bool = True) -> bytes:
    """The records inside a chunk, decompressed and (when the chunk has a CRC) verified."""
    if chunk.compression == "zstd":
        import zstandard

        try:
            data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
        except zstandard.ZstdError as exc:
            raise McapFormatError(f"zstd chunk does not decompress: {exc}") from None
    elif chunk.compression == "lz4":
        import lz4.frame

        try:
            data = lz4.frame.decompress(chunk.data)
        except RuntimeError as exc:
            raise McapFormatError(f"lz4 chunk does not decompress: {exc}") from None
    elif chunk.compression == "":
        data = bytes(chunk.data)
    else:
        raise McapFormatError(f"unknown chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise McapFormatError(f"chunk decompresses to {len(data)} bytes, its header says {chunk.uncompressed_size}")
    if check_crc and chunk.crc and crc32(data) != chunk.crc:
        raise McapFormatError("chunk CRC mismatch")
    return data


def decompress_prefix(compression: str, data: bytes) -> bytes:
    """As much of a cut-off chunk's records as decompresses (zstd and uncompressed only)."""
    if compression == "":
        return bytes(data)
    if compression != "zstd":
        return b""
    import zstandard

    out = []
    dobj = zstandard.ZstdDecompressor().decompressobj()
    step = 1 << 16  # feed in pieces so that output up to a corrupt block is kept
    try:
        for i in range(0, len(data), step):
            out.append(dobj.decompress(data[i:i + step]))
    except zstandard.ZstdError:
        pass
    return b"".join(out)


def iter_records(buf, pos: int = 0, end: int | None = None):
    """(opcode, body_start, body_end) of each record in buf[pos:end]; raises McapFormatError at a record
    whose length runs past the end (the caller decides what a partial record means)."""
    end = len(buf) if end is None else end
    while pos < end:
        if pos + 9 > end:
            raise McapFormatError("partial record header", pos)
        op, length = _OP_LEN.unpack_from(buf, pos)
        body = pos + 9
        if length > end - body:
            raise McapFormatError(f"record (opcode {op:#04x}) of {length} bytes runs past the end", pos)
        yield op, body, body + length
        pos = body + length


def read_exact(f, offset: int, n: int) -> bytes:
    """`n` bytes at `offset`; a length that runs past the end of the file (a damaged length field) is an
    error before anything is read, never an allocation of that size."""
    f.seek(0, os.SEEK_END)
    size = f.tell()
    if offset < 0 or n < 0 or offset + n > size:
        raise McapFormatError(f"{n} bytes at byte {offset} run past the end of the file ({size} bytes)", offset)
    f.seek(offset)
    data = f.read(n)
    if len(data) != n:
        raise McapFormatError(f"file ends {n - len(data)} bytes early", offset)
    return data


def read_record(f, offset: int, expect: int) -> bytes:
    """The body of the record at `offset`, which must have opcode `expect`."""
    op, length = _OP_LEN.unpack(read_exact(f, offset, 9))
    if op != expect:
        raise McapFormatError(f"expected record opcode {expect:#04x}, found {op:#04x}", offset)
    return read_exact(f, offset + 9, length)


def record_at(buf, offset: int, expect: int) -> memoryview:
    """The body of the record at `offset` of an in-memory (or memory-mapped) file, without copying."""
    if offset + 9 > len(buf):
        raise McapFormatError("record header past the end of the file", offset)
    op, length = _OP_LEN.unpack_from(buf, offset)
    if op != expect:
        raise McapFormatError(f"expected record opcode {expect:#04x}, found {op:#04x}", offset)
    if offset + 9 + length > len(buf):
        raise McapFormatError("record runs past the end of the file", offset)
    return memoryview(buf)[offset + 9:offset + 9 + length]


def read_footer(f, size: int) -> tuple[bytes, int, int]:
    """(the footer record's bytes, summary_start, summary_crc) of a complete file. Raises
    McapFormatError when the file does not end with a footer and the closing magic (cut short)."""
    if size < len(MAGIC) * 2 + FOOTER_RECORD_SIZE:
        raise McapFormatError("file too short to hold an MCAP footer")
    tail = read_exact(f, size - FOOTER_RECORD_SIZE - len(MAGIC), FOOTER_RECORD_SIZE + len(MAGIC))
    if tail[-8:] != MAGIC or tail[0] != FOOTER:
        raise McapFormatError("no footer and closing magic at the end of the file")
    summary_start, _summary_offset_start, summary_crc = struct.unpack_from("<QQI", tail, 9)
    return tail[:FOOTER_RECORD_SIZE], summary_start, summary_crc


def read_summary(f, size: int) -> SummarySection | None:
    """The summary section of a complete file (None when the file was written without one). Raises
    McapFormatError when the file does not end with a footer and the closing magic (cut short)."""
    footer, summary_start, summary_crc = read_footer(f, size)
    if summary_start == 0:
        return None
    footer_at = size - FOOTER_RECORD_SIZE - len(MAGIC)
    if not len(MAGIC) <= summary_start <= footer_at:
        raise McapFormatError(f"footer points at summary offset {summary_start} outside the file")
    buf = read_exact(f, summary_start, footer_at - summary_start)
    if summary_crc and crc32(footer[:-4], crc32(buf)) != summary_crc:
        raise McapFormatError("summary CRC mismatch (the index at the end of the file was changed)")
    out = SummarySection()
    for op, b, e in iter_records(buf):
        if op == SCHEMA:
            s = parse_schema(buf, b, e)
            out.schemas[s.id] = s
        elif op == CHANNEL:
            ch = parse_channel(buf, b, e)
            out.channels[ch.id] = ch
        elif op == CHUNK_INDEX:
            out.chunks.append(_parse_chunk_index(buf, b, e))
        elif op == STATISTICS:
            out.statistics = _parse_statistics(buf, b, e)
        elif op == METADATA_INDEX:
            c = _Cursor(buf, b, e)
            offset, length = c.u64(), c.u64()
            out.metadata.append((c.string(), offset, length))
    return out


def _parse_chunk_index(buf, pos: int, end: int) -> ChunkIndex:
    c = _Cursor(buf, pos, end)
    start, stop, offset, length = c.u64(), c.u64(), c.u64(), c.u64()
    n = c.u32()
    sub = _Cursor(buf, c._take(n), c.pos)
    offsets = {}
    while sub.pos < sub.end:
        ch = sub.u16()
        offsets[ch] = sub.u64()
    mi_len = c.u64()
    return ChunkIndex(start, stop, offset, length, offsets, mi_len, c.string())


def _parse_statistics(buf, pos: int, end: int) -> Statistics:
    c = _Cursor(buf, pos, end)
    msg, schemas, channels, att, meta, chunks = c.u64(), c.u16(), c.u32(), c.u32(), c.u32(), c.u32()
    start, stop = c.u64(), c.u64()
    n = c.u32()
    sub = _Cursor(buf, c._take(n), c.pos)
    counts = {}
    while sub.pos < sub.end:
        ch = sub.u16()
        counts[ch] = sub.u64()
    return Statistics(msg, schemas, channels, att, meta, chunks, start, stop, counts)


def parse_message_index(body: bytes):
    """(channel_id, (n, 2) uint64 array of [log_time, offset in the chunk's records])."""
    import numpy as np

    c = _Cursor(body)
    channel = c.u16()
    n = c.u32()
    if n % 16 or n > len(body) - 6:
        raise McapFormatError("malformed message index")
    return channel, np.frombuffer(body, dtype="<u8", count=n // 8, offset=6).reshape(-1, 2)


class Scan:
    """Reads a file's top-level records from the start until the data ends or stops making sense.

    `records()` yields (offset, opcode, body). Afterwards: `stop` says why it ended ("footer" for a
    complete file, "end of file", or what was wrong), `valid_end` is the byte after the last whole
    record, and `partial` is (offset, opcode, available body bytes) of a record cut off by the end of
    the file, if any.
    """

    def __init__(self, f, size: int):
        self.f, self.size = f, size
        self.stop = ""
        self.valid_end = 0
        self.partial: tuple[int, int, bytes] | None = None

    def records(self):
        f, size = self.f, self.size
        f.seek(0)
        if f.read(len(MAGIC)) != MAGIC:
            self.stop = "no MCAP magic at the start"
            return
        pos = self.valid_end = len(MAGIC)
        while True:
            if pos == size:
                self.stop = "end of file"
                return
            head = f.read(9)
            if len(head) < 9:
                self.stop = "end of file inside a record header"
                return
            op, length = _OP_LEN.unpack(head)
            if op not in KNOWN_OPCODES and op < 0x80:
                self.stop = f"invalid record opcode {op:#04x} at byte {pos}"
                return
            if length > size - pos - 9:
                self.partial = (pos, op, f.read(size - pos - 9))
                self.stop = f"record (opcode {op:#04x}) at byte {pos} cut off by the end of the file"
                return
            body = f.read(length)
            yield pos, op, body
            pos += 9 + length
            self.valid_end = pos
            if op == FOOTER:
                self.stop = "footer"
                return


def parse_partial_chunk(body: bytes) -> tuple[str, bytes] | None:
    """(compression, available compressed records) of a chunk record cut off by the end of the file."""
    c = _Cursor(body)
    try:
        c.u64(), c.u64(), c.u64(), c.u32()
        compression = c.string()
        c.u64()
    except McapFormatError:
        return None
    return compression, bytes(body[c.pos:])
