"""Reads a recorded session back: metadata, topics, messages decoded into teleprev payloads, episodes.

SessionReader opens the file and answers from its summary (metadata, topics, times); the rest is done by
one module each: ordered_messages (messages in log_time order, ties in file order, a few chunks at a
time so memory stays bounded), chunk_batches (decoding consecutive chunks together), chunk_lookup (which
chunks, and where in them, the wanted messages are), chunk_file (a chunk's records, CRC checked),
damage (what `info` verifies), episodes, and scan_index (files written without a summary). A file cut
short by a crash has no summary: opening it raises SessionError pointing at `teleprev recover`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from teleprev.errors import SessionError
from teleprev.messages import Logged
from teleprev.session import records as mr
from teleprev.session.chunk_file import ChunkFile
from teleprev.session.codec import JointStatesDecoder, decoder_for
from teleprev.session.damage import damaged_chunks, data_section_intact
from teleprev.session.episodes import Episode, episodes_from
from teleprev.session.joint_table import JointTable
from teleprev.session.message_selection import ReadRequest
from teleprev.session.ordered_messages import ordered_messages
from teleprev.session.scan_index import index_by_scan
from teleprev.session.writer import TELEPREV_RECORD
from teleprev.topics import EPISODE

_END = 1 << 64


def check_written_by_teleprev(path: str | os.PathLike) -> None:
    """Refuse (SessionError) a file whose header says another program wrote it, before reading the rest:
    what `teleprev recover` checks, whose files have no summary to look for the "teleprev" record in. A
    header too damaged to read passes (recovering such a file is what recover is for)."""
    try:
        with open(path, "rb") as f:
            library = _writer_library(f) if f.read(len(mr.MAGIC)) == mr.MAGIC else ""
    except OSError:
        return  # the command's own open says what is wrong with the path
    if library and not library.startswith("teleprev/"):  # teleprev.session.writer, recover
        raise SessionError(f"not a teleprev session: an MCAP file written by {library}; `teleprev import` reads "
                           "other tools' recordings", str(path))


def _writer_library(f) -> str:
    """The `library` of the file's header record (the program that wrote it), "" when it cannot be read."""
    try:
        body = mr.read_record(f, len(mr.MAGIC), mr.HEADER)
        profile_len = int.from_bytes(body[:4], "little")
        at = 4 + profile_len
        library_len = int.from_bytes(body[at:at + 4], "little")
        return bytes(body[at + 4:at + 4 + library_len]).decode("utf-8", "replace").strip()[:80]
    except (mr.McapFormatError, OSError, ValueError):
        return ""


@dataclass(frozen=True, slots=True)
class TopicInfo:
    topic: str
    schema: str
    message_encoding: str
    message_count: int
    first_ns: int | None  # log time of the first and last message (None without messages)
    last_ns: int | None


class SessionReader:
    def __init__(self, path: str | os.PathLike, *, verify_crc: bool = True, any_mcap: bool = False):
        """Each chunk's CRC is checked as it is read (`verify_crc`), so that a damaged chunk is an error
        naming its time range, never data passed on as if it were whole. An MCAP that another tool wrote
        (no "teleprev" metadata record, which teleprev's writer puts in every file it opens) is refused,
        unless `any_mcap` (`teleprev import` reads those)."""
        self.path = Path(path)
        self.verify_crc = verify_crc
        where = str(self.path)
        if not self.path.exists():
            raise SessionError("no such session file", where)
        if not self.path.is_file():
            raise SessionError("not a file", where)
        self.file_bytes = self.path.stat().st_size
        if self.file_bytes == 0:
            raise SessionError("empty file (the recording never started writing)", where)
        f = open(self.path, "rb")
        try:
            if f.read(len(mr.MAGIC)) != mr.MAGIC:
                raise SessionError("not an MCAP file (no MCAP magic at the start)", where)
            try:
                summary = mr.read_summary(f, self.file_bytes)
            except mr.McapFormatError as exc:
                raise SessionError(f"the file is cut short or damaged ({exc}); run `teleprev recover {where}` "
                                   "to rewrite what it holds into a valid session", where) from None
            if summary is None or (not summary.chunks and summary.statistics and summary.statistics.message_count):
                summary = index_by_scan(
                    f, self.file_bytes, self.path
                )  # written without a summary, or without chunk indexes
            if not any_mcap and not any(name == TELEPREV_RECORD for name, _, _ in summary.metadata):
                library = _writer_library(f)
                raise SessionError(f"not a teleprev session: an MCAP file written by {library or 'another tool'} "
                                   f"(it has no {TELEPREV_RECORD!r} metadata record); `teleprev import` reads "
                                   "other tools' recordings", where)
            chunks = sorted(summary.chunks, key=lambda c: (c.start_ns, c.offset))
            self._file = ChunkFile(f, self.path, min((c.start_ns for c in chunks), default=None),
                                   verify_crc=verify_crc)
        except BaseException:
            f.close()
            raise
        self._summary = summary
        self._chunks = chunks
        self._by_topic: dict[str, list[int]] = {}
        for ch in summary.channels.values():
            self._by_topic.setdefault(ch.topic, []).append(ch.id)

    # --- file-level facts ---

    @cached_property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records by name (a later record of the same name updates an earlier one). Metadata records
        carry no CRC of their own: the data section's (which holds them) is checked first, when the file has
        one, so a changed byte in a rig or a task text is an error, never a value passed on."""
        if self._summary.metadata and self.data_section_intact() is False and not self.damaged_chunks():
            # (a damaged chunk explains the mismatch; reading it is the error that names it)
            raise SessionError("bytes outside the chunks (a metadata record or a message index) were changed: the "
                               f"data section's CRC does not match; `teleprev recover {self.path}` rebuilds the file",
                               str(self.path))
        out: dict[str, dict[str, str]] = {}
        for name, offset, _length in self._summary.metadata:
            try:
                body = mr.read_record(self._file.f, offset, mr.METADATA)
                rec_name, data = mr.parse_metadata(body, 0, len(body))
            except mr.McapFormatError as exc:
                raise SessionError(f"metadata record {name!r} is damaged: {exc}", str(self.path)) from None
            out.setdefault(rec_name, {}).update(data)
        return out

    @cached_property
    def schemas(self) -> dict[str, str]:
        """Topic -> schema name ("" without one), from the summary alone: what `topics` says without
        reading the message indexes for counts and times."""
        out = {}
        for topic, ids in sorted(self._by_topic.items()):
            schema = self._summary.schemas.get(self._summary.channels[ids[0]].schema_id)
            out[topic] = schema.name if schema else ""
        return out

    @cached_property
    def topics(self) -> dict[str, TopicInfo]:
        counts = self._summary.statistics.channel_message_counts if self._summary.statistics else {}
        out = {}
        for topic, ids in sorted(self._by_topic.items()):
            ch = self._summary.channels[ids[0]]
            times = self.log_times(topic)
            n = sum(counts.get(i, 0) for i in ids) if counts else len(times)
            out[topic] = TopicInfo(topic, self.schemas[topic], ch.message_encoding, n,
                                   int(times.min()) if len(times) else None, int(times.max()) if len(times) else None)
        return out

    @property
    def start_ns(self) -> int | None:
        return min((c.start_ns for c in self._chunks), default=None)

    @property
    def end_ns(self) -> int | None:
        return max((c.end_ns for c in self._chunks), default=None)

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9

    def log_times(self, topic: str) -> np.ndarray:
        """Log times (int64 ns) of a topic's messages in file order, from the message indexes (no
        decompression) when the file has them."""
        per_channel = self._index_times
        parts = [per_channel[i] for i in self._by_topic.get(topic, []) if i in per_channel]
        if not parts:
            return np.zeros(0, dtype=np.int64)
        return np.concatenate(parts) if len(parts) > 1 else parts[0]

    @cached_property
    def _index_times(self) -> dict[int, np.ndarray]:
        per_channel: dict[int, list[np.ndarray]] = {}
        for chunk in sorted(self._chunks, key=lambda c: c.offset):
            index = self._file.message_index(chunk)
            if index is not None:
                for ch, entries in index.items():
                    per_channel.setdefault(ch, []).append(entries[:, 0].astype(np.int64))
            else:  # no message index: read the chunk itself
                times: dict[int, list[int]] = {}
                for ch, t in self._file.message_times(chunk):
                    times.setdefault(ch, []).append(t)
                for ch, ts in times.items():
                    per_channel.setdefault(ch, []).append(np.array(ts, dtype=np.int64))
        return {ch: np.concatenate(v) for ch, v in per_channel.items()}

    # --- messages ---

    def messages(
        self, topics: Iterable[str] | None = None, start_ns: int | None = None, end_ns: int | None = None,
        *, tables: dict[str, JointTable] | None = None,
    ) -> Iterator[Logged]:
        """Messages with start_ns <= log_time < end_ns, in log_time order, decoded into teleprev
        payloads. With `topics` None, every topic whose schema teleprev reads.

        `tables` (topic -> JointTable, foxglove.JointStates topics only) reads those topics in the same
        pass without yielding them: each message's stamp and positions are appended to its topic's
        table instead, in the order they would have been yielded (a cheaper decode when a caller only
        needs the values)."""
        tables = tables or {}
        decoders, names = self._decoders(topics)
        if tables:
            table_decoders, table_names = self._decoders(list(tables))
            decoders.update(table_decoders)
            names.update(table_names)
        tabled = self._table_channels(tables, decoders)
        lo = 0 if start_ns is None else int(start_ns)
        hi = _END if end_ns is None else int(end_ns)
        wanted = frozenset(decoders)
        yield from ordered_messages(self._file, self._chunks, ReadRequest(decoders, names, lo, hi, wanted, tabled))

    def _table_channels(self, tables: dict[str, JointTable], decoders) -> dict[int, JointTable]:
        """channel id -> the table its messages go to."""
        out = {}
        for topic, table in tables.items():
            for ch in self._by_topic[topic]:
                if not isinstance(decoders.get(ch), JointStatesDecoder):
                    raise SessionError(f"topic {topic} is not foxglove.JointStates: it cannot be read as a table",
                                       str(self.path))
                out[ch] = table
        return out

    def _decoders(self, topics: Iterable[str] | None):
        decoders, names = {}, {}
        if topics is None:
            ids = [i for ids in self._by_topic.values() for i in ids]
            strict = False
        else:
            if isinstance(topics, str):
                topics = [topics]
            ids = []
            for t in topics:
                if t not in self._by_topic:
                    raise SessionError(f"no topic {t!r} in this session (topics: {', '.join(sorted(self._by_topic))})",
                                       str(self.path))
                ids.extend(self._by_topic[t])
            strict = True
        for i in ids:
            ch = self._summary.channels[i]
            schema = self._summary.schemas.get(ch.schema_id)
            try:
                if schema is None:
                    raise ValueError("channel has no schema")
                decoders[i] = decoder_for(schema.name, schema.encoding, schema.data, ch.message_encoding, ch.metadata)
            except ValueError as exc:
                if strict:
                    raise SessionError(f"topic {ch.topic}: {exc}", str(self.path)) from None
                continue
            names[i] = ch.topic
        return decoders, names

    # --- damage ---

    def describe_chunk(self, chunk: mr.ChunkIndex) -> str:
        """Where a chunk is, in the words a user needs: its log times from the session's start."""
        return self._file.describe(chunk)

    def data_section_intact(self) -> bool | None:
        """Whether the bytes before the summary still match the CRC the writer stored in the data-end
        record (None when the file has none): reads the whole data section once (3 GB/s), then remembers."""
        return self._data_section_intact

    @cached_property
    def _data_section_intact(self) -> bool | None:
        return data_section_intact(self._file, self.file_bytes)

    def damaged_chunks(self) -> list[tuple[mr.ChunkIndex, str]]:
        """Every chunk that does not read back whole (CRC, compression, records), with why; reads the
        whole file once."""
        return damaged_chunks(self._file, self._chunks)

    # --- episodes ---

    def episodes(self) -> list[Episode]:
        """Episodes from /events/episode: start, stop, discard and outcome events by episode index."""
        if EPISODE not in self._by_topic:
            return []
        return episodes_from(self.messages([EPISODE]), self.path)

    # --- lifecycle ---

    def release_pages(self) -> None:
        """Drop the file's pages from this process's resident set (see ChunkFile.release_pages)."""
        self._file.release_pages()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> SessionReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
