"""Rewrites a session file cut short (crash, kill, power loss) into a valid, complete MCAP.

The source is read record by record from the start until the data stops making sense: every complete
message, with the schemas, channels, metadata and attachments found, goes to the new file; a chunk cut
off by the end of the file gives up the messages that decompress whole. The source is never modified.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from teleprev.errors import SessionError
from teleprev.session import records as mr

RECOVER_RECORD = "recover"  # metadata record describing what was recovered


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
        if ch is None:
            raise mr.McapFormatError(f"message on unknown channel {cid}")
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
    `<name>.recovered.mcap` next to it) and say what was saved."""
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
        if f.read(len(mr.MAGIC)) != mr.MAGIC:
            raise SessionError("not an MCAP file (no MCAP magic at the start); nothing to recover", str(src))
        try:
            out = open(dst, "xb")
        except OSError as exc:
            raise SessionError(f"cannot create the recovered file: {exc.strerror}", str(dst)) from None
        try:
            result = _copy(f, size, out, Writer, CompressionType)
        except BaseException:
            out.close()
            dst.unlink(missing_ok=True)  # our own half-written output, never the source
            raise
    result.src, result.dst = src, dst
    return result


def _copy(f, size: int, out, Writer, CompressionType) -> RecoverResult:
    from teleprev import __version__

    w = Writer(out, compression=CompressionType.ZSTD)
    w.start(profile="", library=f"teleprev/{__version__} recover")
    copier = _Copier(w)
    scan = mr.Scan(f, size)
    metadata: list[str] = []
    stop = ""
    salvaged = 0
    for offset, op, body in scan.records():
        try:
            if op == mr.CHUNK:
                copier.inner_records(mr.decompress(mr.parse_chunk(body, 0, len(body))))
            elif op == mr.SCHEMA:
                copier.schema(mr.parse_schema(body, 0, len(body)))
            elif op == mr.CHANNEL:
                copier.channel(mr.parse_channel(body, 0, len(body)))
            elif op == mr.MESSAGE:
                copier.message(body, 0, len(body))
            elif op == mr.METADATA:
                name, data = mr.parse_metadata(body, 0, len(body))
                w.add_metadata(name, data)
                metadata.append(name)
            elif op == mr.ATTACHMENT:
                a = mr.parse_attachment(body, 0, len(body))
                w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
            elif op == mr.DATA_END:
                stop = "footer"
                break
        except mr.McapFormatError as exc:
            stop = f"record (opcode {op:#04x}) at byte {offset} does not make sense: {exc}"
            scan.valid_end = offset
            break
    else:
        stop = scan.stop
        if scan.partial is not None and scan.partial[1] == mr.CHUNK:
            salvaged = _salvage(copier, scan.partial[2])
    complete = stop == "footer"
    w.add_metadata(RECOVER_RECORD, {
        "source_bytes": str(size),
        "valid_bytes": str(size if complete else scan.valid_end),
        "messages": str(sum(copier.counts.values())),
        "salvaged_from_cut_chunk": str(salvaged),
        "stop": stop,
        "recovered_ns": str(time.time_ns()),
    })
    w.finish()
    out.flush()
    os.fsync(out.fileno())
    out.close()
    return RecoverResult(
        Path(), Path(), complete, dict(sorted(copier.counts.items())), copier.start_ns, copier.end_ns, size,
        size if complete else scan.valid_end, salvaged, metadata, stop,
    )


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
