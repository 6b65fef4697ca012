"""Rewrites a session file cut short (crash, kill, power loss) or damaged (flipped bytes) into a valid,
complete MCAP.

The source is read record by record from the start: every complete message, with the schemas,
channels, metadata and attachments found, goes to the new file. A record that does not make sense (a
chunk whose CRC or compression fails, a length that runs astray, an unknown opcode) is skipped by
resynchronising on the next record that proves itself whole (a chunk that decompresses to its CRC, a
metadata record followed by a record header), so only the damaged range is lost; each such range is
reported with the log times it lies between. A chunk cut off by the end of the file gives up the
messages that decompress whole. The output is written under a hidden name and renamed into place when
complete, so a recover that is killed leaves no half-written file; the source is never modified.
"""

from __future__ import annotations

import mmap
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

from teleprev.errors import SessionError
from teleprev.session import records as mr

RECOVER_RECORD = "recover"  # metadata record describing what was recovered


@dataclass
class Damage:
    """Bytes [start, end) of the source skipped as damaged, why, and the log times of the last message
    kept before them and the first kept after them (None at either end of the session)."""

    start: int
    end: int
    why: str
    after_ns: int | None = None
    before_ns: int | None = None

    def describe(self, t0: int | None) -> str:
        def at(t):
            return "?" if t is None or t0 is None else f"{(t - t0) / 1e9:.3f}"

        return (f"bytes {self.start}-{self.end} ({self.why}): messages logged between {at(self.after_ns)} and "
                f"{at(self.before_ns)} s into the session lost")


@dataclass
class RecoverResult:
    src: Path
    dst: Path
    complete: bool  # the source already ended with a footer (nothing was missing)
    messages: dict[str, int]  # messages saved per topic
    start_ns: int | None  # log time span kept
    end_ns: int | None
    source_bytes: int
    valid_bytes: int  # bytes of the source up to the last whole record read
    salvaged: int  # messages taken from a chunk cut off by the end of the file
    metadata: list[str] = field(default_factory=list)  # names of metadata records kept
    stop: str = ""  # why reading stopped
    damaged: list[Damage] = field(default_factory=list)  # ranges skipped in the middle of the file
    unknown_channel: int = 0  # messages whose channel was defined only in a damaged range

    @property
    def total(self) -> int:
        return sum(self.messages.values())

    @property
    def span_s(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9


def default_destination(src: Path) -> Path:
    name = src.name[:-5] if src.name.endswith(".mcap") else src.name
    return src.with_name(f"{name}.recovered.mcap")


class _Copier:
    """Re-registers schemas and channels in the destination on first sight and copies messages raw."""

    def __init__(self, writer):
        self.w = writer
        self.schemas: dict[int, mr.SchemaRecord] = {}
        self.channels: dict[int, mr.ChannelRecord] = {}
        self._schema_ids: dict[int, int] = {}
        self._channel_ids: dict[int, int] = {}
        self.counts: dict[str, int] = {}
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.last_ns: int | None = None  # log time of the last message copied (file order)
        self.unknown_channel = 0
        self.pending: Damage | None = None  # a damaged range waiting for the first message after it

    def schema(self, s: mr.SchemaRecord) -> None:
        if s.id == 0:
            raise mr.McapFormatError("schema record with id 0")
        self.schemas[s.id] = s

    def channel(self, c: mr.ChannelRecord) -> None:
        if c.schema_id and c.schema_id not in self.schemas:
            raise mr.McapFormatError(f"channel {c.topic!r} refers to unknown schema {c.schema_id}")
        self.channels[c.id] = c

    def message(self, buf, b: int, e: int) -> None:
        if e - b < 22:
            raise mr.McapFormatError("message record too short")
        cid, seq, log_time, publish_time = mr.MESSAGE_HEADER.unpack_from(buf, b)
        ch = self.channels.get(cid)
        if ch is None:  # its channel record was in a damaged range: the message cannot be decoded
            self.unknown_channel += 1
            return
        new_id = self._channel_ids.get(cid)
        if new_id is None:
            sid = 0
            if ch.schema_id:
                sid = self._schema_ids.get(ch.schema_id)
                if sid is None:
                    s = self.schemas[ch.schema_id]
                    sid = self._schema_ids[ch.schema_id] = self.w.register_schema(s.name, s.encoding, s.data)
            new_id = self._channel_ids[cid] = self.w.register_channel(ch.topic, ch.message_encoding, sid, ch.metadata)
        self.w.add_message(new_id, log_time, bytes(buf[b + 22:e]), publish_time, seq)
        self.counts[ch.topic] = self.counts.get(ch.topic, 0) + 1
        self.last_ns = log_time
        if self.pending is not None:
            self.pending.before_ns = log_time
            self.pending = None
        if self.start_ns is None or log_time < self.start_ns:
            self.start_ns = log_time
        if self.end_ns is None or log_time > self.end_ns:
            self.end_ns = log_time

    def inner_records(self, buf) -> None:
        """Schemas, channels and messages of a decompressed chunk, up to the first that does not parse."""
        for op, b, e in mr.iter_records(buf):
            if op == mr.SCHEMA:
                self.schema(mr.parse_schema(buf, b, e))
            elif op == mr.CHANNEL:
                self.channel(mr.parse_channel(buf, b, e))
            elif op == mr.MESSAGE:
                self.message(buf, b, e)


def recover(src: str | os.PathLike, dst: str | os.PathLike | None = None) -> RecoverResult:
    """Write every complete message of `src` into a new valid MCAP at `dst` (default
    `<name>.recovered.mcap` next to it) and say what was saved and what was lost where."""
    from mcap.writer import CompressionType, Writer

    src = Path(src)
    if not src.is_file():
        raise SessionError("no such session file", str(src))
    dst = default_destination(src) if dst is None else Path(dst)
    if dst.resolve() == src.resolve():
        raise SessionError("the recovered file must not replace its source", str(dst))
    if dst.exists():
        raise SessionError("already exists; choose another output with --out or remove it", str(dst))
    size = src.stat().st_size
    with open(src, "rb") as f:
        head = f.read(len(mr.MAGIC) + 1)
        if not _looks_like_mcap(head):
            raise SessionError("not an MCAP file (no MCAP magic at the start); nothing to recover", str(src))
        tmp = dst.with_name(f".{dst.name}.partial-{os.getpid()}")
        try:
            out = open(tmp, "xb")
        except OSError as exc:
            raise SessionError(f"cannot create the recovered file: {exc.strerror}", str(dst)) from None
        try:
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
                result = _copy(data, size, out, Writer, CompressionType)
            if dst.exists():
                raise SessionError("appeared while recovering; choose another output with --out", str(dst))
            os.rename(tmp, dst)
        except BaseException:
            out.close()
            tmp.unlink(missing_ok=True)  # our own half-written output, never the source
            raise
    result.src, result.dst = src, dst
    return result


def _looks_like_mcap(head: bytes) -> bool:
    """The MCAP magic, or (a flipped byte or two in it) a header record right after it."""
    if head[:len(mr.MAGIC)] == mr.MAGIC:
        return True
    if len(head) <= len(mr.MAGIC) or head[len(mr.MAGIC)] != mr.HEADER:
        return False
    return sum(a != b for a, b in zip(head, mr.MAGIC)) <= 2


class _Source:
    """Top-level records of the source, strictly parsed, and where the next whole record is after damage."""

    CANDIDATES = re.compile(bytes([ord("["), mr.CHUNK, mr.METADATA, mr.DATA_END, ord("]")]))

    def __init__(self, data, size: int):
        self.data, self.size = data, size

    def header(self, pos: int) -> tuple[int, int] | None:
        """(opcode, body end) of the record at pos if its header is sane and it fits in the file."""
        if pos + 9 > self.size:
            return None
        op, length = mr._OP_LEN.unpack_from(self.data, pos)
        if (op not in mr.KNOWN_OPCODES and op < 0x80) or op == 0 or length > self.size - pos - 9:
            return None
        return op, pos + 9 + length

    def chunk(self, pos: int, end: int) -> bytes:
        """The records of a whole chunk: its fields fill the record exactly and its CRC matches."""
        body = memoryview(self.data)[pos + 9:end]
        try:
            c = mr.parse_chunk(body, 0, len(body))
            used = 8 + 8 + 8 + 4 + 4 + len(c.compression.encode()) + 8 + len(c.data)
            if used != len(body):
                raise mr.McapFormatError(f"chunk fields fill {used} of its {len(body)} bytes")
            if c.start_ns > c.end_ns:
                raise mr.McapFormatError("chunk ends before it starts")
            return mr.decompress(c)
        finally:
            body.release()

    def proves_whole(self, pos: int) -> bool:
        """A record at pos that can be trusted after damage: a chunk that checks out, or a metadata or
        data-end record followed by another record header (or the end of the file)."""
        found = self.header(pos)
        if found is None:
            return False
        op, end = found
        try:
            if op == mr.CHUNK:
                self.chunk(pos, end)
                return True
            if op == mr.METADATA:
                mr.parse_metadata(self.data, pos + 9, end)
            elif op == mr.DATA_END:
                if end - pos - 9 != 4:
                    return False
            else:
                return False
        except mr.McapFormatError:
            return False
        return end == self.size or self.header(end) is not None

    def resync(self, pos: int) -> int | None:
        """The first position at or after pos where a record proves itself whole."""
        for m in self.CANDIDATES.finditer(self.data, pos):
            if self.proves_whole(m.start()):
                return m.start()
        return None


def _copy(data, size: int, out, Writer, CompressionType) -> RecoverResult:
    from teleprev import __version__

    w = Writer(out, compression=CompressionType.ZSTD, enable_data_crcs=True)
    w.start(profile="", library=f"teleprev/{__version__} recover")
    copier = _Copier(w)
    _known_channels(data, size, copier)
    src = _Source(data, size)
    metadata: list[str] = []
    damaged: list[Damage] = []
    stop = ""
    salvaged = 0
    pos = valid_end = len(mr.MAGIC)
    while True:
        if pos >= size:
            stop = "end of file"
            break
        found = src.header(pos)
        why = ""
        if found is None:
            why = _why_not_a_record(data, pos, size)
        else:
            op, end = found
            try:
                if op == mr.CHUNK:
                    copier.inner_records(src.chunk(pos, end))
                elif op == mr.SCHEMA:
                    copier.schema(mr.parse_schema(data, pos + 9, end))
                elif op == mr.CHANNEL:
                    copier.channel(mr.parse_channel(data, pos + 9, end))
                elif op == mr.MESSAGE:
                    copier.message(data, pos + 9, end)
                elif op == mr.METADATA:
                    name, meta = mr.parse_metadata(data, pos + 9, end)
                    w.add_metadata(name, meta)
                    metadata.append(name)
                elif op == mr.ATTACHMENT:
                    a = mr.parse_attachment(data, pos + 9, end)
                    w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
            except mr.McapFormatError as exc:
                why = f"record (opcode {op:#04x}) at byte {pos} does not make sense: {exc}"
            else:
                pos = valid_end = end
                if op == mr.DATA_END:
                    stop = "footer"
                    break
                continue
        nxt = src.resync(pos + 1)
        if nxt is None:  # nothing whole after it: the end of what the file holds
            stop = why
            if found is None and pos + 9 <= size:
                op = data[pos]
                if op == mr.CHUNK:
                    salvaged = _salvage(copier, bytes(data[pos + 9:size]))
            break
        damaged.append(Damage(pos, nxt, why.split(" does not make sense: ")[-1], copier.last_ns))
        copier.pending = damaged[-1]
        pos = nxt
    complete = stop == "footer" and not damaged
    w.add_metadata(RECOVER_RECORD, {
        "source_bytes": str(size),
        "valid_bytes": str(size if stop == "footer" else valid_end),
        "messages": str(sum(copier.counts.values())),
        "salvaged_from_cut_chunk": str(salvaged),
        "damaged": "; ".join(f"{d.start}-{d.end}: {d.why}" for d in damaged),
        "stop": stop,
        "recovered_ns": str(time.time_ns()),
    })
    w.finish()
    out.flush()
    os.fsync(out.fileno())
    out.close()
    return RecoverResult(
        Path(), Path(), complete, dict(sorted(copier.counts.items())), copier.start_ns, copier.end_ns, size,
        size if stop == "footer" else valid_end, salvaged, metadata, stop, damaged, copier.unknown_channel,
    )


def _why_not_a_record(data, pos: int, size: int) -> str:
    if pos + 9 > size:
        return "end of file inside a record header"
    op, length = mr._OP_LEN.unpack_from(data, pos)
    if (op not in mr.KNOWN_OPCODES and op < 0x80) or op == 0:
        return f"invalid record opcode {op:#04x} at byte {pos}"
    return f"record (opcode {op:#04x}) at byte {pos} cut off by the end of the file"


def _known_channels(data, size: int, copier: _Copier) -> None:
    """A complete file repeats its schemas and channels in the summary: read them first, so that messages
    whose channel record was in a damaged chunk can still be kept."""
    try:
        summary = mr.read_summary(data, size)  # an mmap reads like a file
    except mr.McapFormatError:
        return
    if summary is None:
        return
    for sc in summary.schemas.values():
        if sc.id:
            copier.schemas.setdefault(sc.id, sc)
    for ch in summary.channels.values():
        if not ch.schema_id or ch.schema_id in copier.schemas:
            copier.channels.setdefault(ch.id, ch)


def _salvage(copier: _Copier, partial_body: bytes) -> int:
    """Messages that decompress whole from a chunk cut off by the end of the file."""
    parsed = mr.parse_partial_chunk(partial_body)
    if parsed is None:
        return 0
    compression, data = parsed
    buf = mr.decompress_prefix(compression, data)
    before = sum(copier.counts.values())
    try:
        copier.inner_records(buf)
    except mr.McapFormatError:
        pass  # the records that parsed before it are kept; the rest is the cut
    return sum(copier.counts.values()) - before
