"""Reads a recorded session back: metadata, topics, messages decoded into teleprev payloads, episodes.

Messages come in log_time order (ties in file order), a few chunks at a time (see _BATCH_CHUNKS), so
memory stays bounded by a few chunks. A file cut short by a crash has no summary: opening it raises
SessionError pointing at `teleprev recover`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from teleprev.errors import SessionError
from teleprev.messages import Logged
from teleprev.session import records as mr
from teleprev.session.chunk_file import ChunkFile
from teleprev.session.codec import JointStatesDecoder, decoder_for
from teleprev.session.damage import damaged_chunks, data_section_intact
from teleprev.session.episodes import Episode, episodes_from
from teleprev.session.joint_table import JointTable
from teleprev.session.scan_index import index_by_scan
from teleprev.topics import EPISODE

_END = 1 << 64
_BATCH_CHUNKS = 8  # chunks decoded together at most (each channel's messages of them in one batch),
_BATCH_BYTES = 8 << 20  # and their compressed bytes at most; release_pages after each batch
_I64_END = (1 << 63) - 1  # log times beyond int64 (year 2262) are not expected
_HEAD_BYTES = np.arange(23)  # a message record's opcode, length, channel, sequence and log time


@dataclass(frozen=True, slots=True)
class TopicInfo:
    topic: str
    schema: str
    message_encoding: str
    message_count: int
    first_ns: int | None  # log time of the first and last message (None without messages)
    last_ns: int | None


class SessionReader:
    def __init__(self, path: str | os.PathLike, *, verify_crc: bool = True):
        """Each chunk's CRC is checked as it is read (`verify_crc`), so that a damaged chunk is an error
        naming its time range, never data passed on as if it were whole."""
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
                summary = index_by_scan(f, self.file_bytes, self.path)  # written without a summary, or without chunk indexes
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
        """Metadata records by name (a later record of the same name updates an earlier one)."""
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
        reading = _Reading(decoders, names, lo, hi, wanted, tabled)
        batch: list[mr.ChunkIndex] = []  # consecutive chunks that overlap no other: decoded together
        for group in self._chunk_groups(lo, hi, wanted):
            if len(group) == 1:
                batch.append(group[0])
                if len(batch) < _BATCH_CHUNKS and sum(c.length for c in batch) < _BATCH_BYTES:
                    continue
                yield from self._decode_batch(batch, reading)
            else:
                if batch:
                    yield from self._decode_batch(batch, reading)
                yield from self._decode_group(group, reading)
            batch = []
            self._file.release_pages()
        if batch:
            yield from self._decode_batch(batch, reading)

    def _chunk_groups(self, lo: int, hi: int, wanted) -> Iterator[list[mr.ChunkIndex]]:
        """The chunks that may hold wanted messages in [lo, hi), in time order, as groups of chunks that
        overlap in time (most groups are one chunk)."""
        group: list = []
        group_end = -1
        for chunk in self._chunks:
            if chunk.end_ns < lo or chunk.start_ns >= hi:
                continue
            if chunk.message_index_offsets and wanted.isdisjoint(chunk.message_index_offsets):
                continue
            if group and chunk.start_ns >= group_end:
                yield group
                group = []
            group.append(chunk)
            group_end = max(group_end, chunk.end_ns) if len(group) > 1 else chunk.end_ns
        if group:
            yield group

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
                decoders[i] = decoder_for(schema.name, schema.encoding, schema.data, ch.message_encoding)
            except ValueError as exc:
                if strict:
                    raise SessionError(f"topic {ch.topic}: {exc}", str(self.path)) from None
                continue
            names[i] = ch.topic
        return decoders, names

    def _decode_group(self, group, reading: _Reading) -> Iterator[Logged]:
        if len(group) == 1:
            yield from self._decode_chunk(group[0], reading)
            return
        # Chunks overlapping in time: merge them (a stable sort keeps file order for equal times). Tabled
        # topics are decoded as messages here too, then appended to their tables in the merged order.
        merged = [m for c in sorted(group, key=lambda c: c.offset)
                  for m in self._decode_chunk(c, reading.untabled())]
        merged.sort(key=_logged_time)
        by_topic = {self._summary.channels[ch].topic: table for ch, table in reading.tabled.items()}
        for m in merged:
            table = by_topic.get(m.topic)
            if table is None:
                yield m
            else:
                table.append(m.payload.stamp_ns, m.payload.positions)

    def _decode_batch(self, chunks: list[mr.ChunkIndex], reading: _Reading) -> Iterator[Logged]:
        """Consecutive chunks that overlap no other, each channel's messages of all of them decoded in one
        batch; what decoding them chunk by chunk gives, errors included: a chunk that does not read is
        raised after the messages of the chunks before it, and a message that does not decode sends the
        batch back to chunk by chunk, which fails where it always did."""
        located, error = [], None
        for chunk in chunks:
            try:
                located.append(self._locate(chunk, reading))
            except SessionError as exc:
                error = exc
                break
        try:
            messages = self._decode_located(_Located.join(located), reading)
        except SessionError:
            for one in located:
                yield from self._decode_located(one, reading)
        else:
            yield from messages
        if error is not None:
            raise error

    def _decode_chunk(self, chunk: mr.ChunkIndex, reading: _Reading) -> list[Logged]:
        return self._decode_located(self._locate(chunk, reading), reading)

    def _locate(self, chunk: mr.ChunkIndex, reading: _Reading) -> _Located:
        """The chunk's messages on wanted channels in [lo, hi), as bytes, and their order."""
        buf = self._file.records(chunk)
        located = self._locate_indexed(chunk, buf, reading.wanted, reading.lo, reading.hi)
        if located is None:
            located = self._locate_sequential(chunk, buf, reading.wanted, reading.lo, reading.hi)
        return _Located(*located)

    def _decode_located(self, located: _Located, reading: _Reading) -> list[Logged]:
        """The located messages decoded, in log time order (file order for equal times); those of tabled
        channels go to their tables instead, once every channel has decoded. Each channel's messages
        are decoded together (see JointStatesDecoder.batch)."""
        names = reading.names
        order = located.order
        decoded, tabled = {}, []
        for ch, datas in located.per_channel.items():
            decoder, table = reading.decoders[ch], reading.tabled.get(ch)
            if table is None:
                decoded[ch] = self._decode_all(decoder, getattr(decoder, "batch", None), datas, names[ch], ch, order)
            else:
                tabled.append((table, ch, self._decode_all(decoder, decoder.columns, datas, names[ch], ch, order)))
        for table, ch, (stamps, positions) in tabled:
            table.extend_in_order(stamps, positions, order.indices(ch))
        return [Logged(names[c], t, decoded[c][k]) for c, k, t in order.entries(exclude=reading.tabled)]

    def _locate_indexed(self, chunk, buf: bytes, wanted, lo: int, hi: int):
        """Per channel, the wanted messages' bytes, and the (channel, index, log time) order, found
        through the message index with numpy; None when the chunk has no usable index (then the chunk
        is parsed record by record). Every index entry is checked against the record it points at."""
        index = self._file.message_index(chunk)
        if index is None:
            return None
        sel = [(ch, e) for ch, e in index.items() if ch in wanted]
        if not sel:
            return {}, _Order.empty()
        entries = np.concatenate([e for _, e in sel]).astype(np.int64)
        chans = np.concatenate([np.full(len(e), ch, dtype=np.int64) for ch, e in sel])
        ks = np.concatenate([np.arange(len(e)) for _, e in sel])
        times, offs = entries[:, 0], entries[:, 1]
        keep = None
        if lo > 0 or hi < _I64_END:
            keep = (times >= min(lo, _I64_END)) & (times < min(hi, _I64_END))
        if keep is not None:
            times, offs, chans = times[keep], offs[keep], chans[keep]
        n = len(buf)
        if len(offs) and (offs.min() < 0 or offs.max() + 9 + 22 > n):
            return None
        a = np.frombuffer(buf, np.uint8)
        head = a[offs[:, None] + _HEAD_BYTES]  # opcode, length (8), channel (2), sequence (4), log time (8)
        lengths = np.ascontiguousarray(head[:, 1:9]).view("<u8")[:, 0].astype(np.int64)
        channel = np.ascontiguousarray(head[:, 9:11]).view("<u2")[:, 0]
        logged = np.ascontiguousarray(head[:, 15:23]).view("<u8")[:, 0].astype(np.int64)
        ends = offs + 9 + lengths
        if not ((head[:, 0] == mr.MESSAGE).all() and (lengths >= 22).all() and (ends <= n).all()
                and (channel == chans).all() and (logged == times).all()):
            return None
        # the entries come channel after channel: one run of each wanted channel with messages left
        run_starts = np.flatnonzero(np.diff(chans, prepend=-1))
        run_ends = [*run_starts[1:].tolist(), len(chans)]
        starts, stops = (offs + 31).tolist(), ends.tolist()
        per_channel: dict[int, list[bytes]] = {}
        for a, b in zip(run_starts.tolist(), run_ends):
            per_channel[int(chans[a])] = [buf[s0:e0] for s0, e0 in zip(starts[a:b], stops[a:b])]
        if keep is not None:  # renumber within each channel after filtering
            ks = np.arange(len(chans)) - np.repeat(run_starts, np.diff([*run_starts.tolist(), len(chans)]))
        ordering = np.lexsort((offs, times))
        return per_channel, _Order(chans[ordering], ks[ordering], times[ordering])

    def _locate_sequential(self, chunk, buf: bytes, wanted, lo: int, hi: int):
        per_channel: dict[int, list[bytes]] = {}
        order: list[tuple[int, int, int]] = []  # (channel, index in that channel's list, log time)
        head = mr.MESSAGE_HEADER.unpack_from
        for op, b, e in self._file.iter_records(chunk, buf):
            if op == mr.MESSAGE:
                ch, _seq, t, _pub = head(buf, b)
                if ch in wanted and lo <= t < hi:
                    datas = per_channel.get(ch)
                    if datas is None:
                        datas = per_channel[ch] = []
                    order.append((ch, len(datas), t))
                    datas.append(buf[b + 22:e])
        order.sort(key=_third)  # stable: file order for equal times
        return per_channel, _Order.of(order)

    def _decode_all(self, decoder, batch, datas: list[bytes], topic: str, channel: int, order: _Order):
        """`batch(datas)` (or `decoder` on each message when batch is None); when that fails, the error
        names the first message that does not decode."""
        try:
            return batch(datas) if batch is not None else [decoder(d) for d in datas]
        except (ValueError, IndexError, TypeError, KeyError):
            pass
        for data, t in zip(datas, order.times_by_index(channel)):  # find the message that does not decode
            try:
                decoder(data)
            except (ValueError, IndexError, TypeError, KeyError) as exc:
                raise SessionError(f"message on {topic} at log time {t} does not decode: {exc}",
                                   str(self.path)) from None
        raise SessionError(f"messages on {topic} do not decode", str(self.path))

    # --- damage ---

    def describe_chunk(self, chunk: mr.ChunkIndex) -> str:
        """Where a chunk is, in the words a user needs: its log times from the session's start."""
        return self._file.describe(chunk)

    def data_section_intact(self) -> bool | None:
        """Whether the bytes before the summary still match the CRC the writer stored in the data-end
        record (None when the file has none): reads the whole data section once."""
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


class _Order:
    """Wanted messages of one or more chunks in log time order (file order for equal times): per message its
    channel, its index among that channel's messages in file order, and its log time (int64 arrays)."""

    __slots__ = ("channels", "indices_", "times")

    def __init__(self, channels: np.ndarray, indices: np.ndarray, times: np.ndarray):
        self.channels, self.indices_, self.times = channels, indices, times

    @classmethod
    def empty(cls) -> _Order:
        none = np.zeros(0, dtype=np.int64)
        return cls(none, none, none)

    @classmethod
    def of(cls, entries: list[tuple[int, int, int]]) -> _Order:
        if not entries:
            return cls.empty()
        channels, indices, times = zip(*entries)
        try:
            log_times = np.array(times, dtype=np.int64)
        except OverflowError:  # log times past int64 (year 2262): kept as Python integers
            log_times = np.array(times, dtype=object)
        return cls(np.array(channels, dtype=np.int64), np.array(indices, dtype=np.int64), log_times)

    def after(self, counts: dict[int, int]) -> _Order:
        """This order with each channel's indices moved past `counts[channel]` earlier messages."""
        if not any(counts.values()):
            return self
        shift = np.zeros(max(counts) + 1, dtype=np.int64)
        shift[list(counts)] = list(counts.values())
        return _Order(self.channels, self.indices_ + shift[self.channels], self.times)

    @classmethod
    def concat(cls, orders: list[_Order]) -> _Order:
        return cls(*(np.concatenate(column) for column in zip(*((o.channels, o.indices_, o.times) for o in orders))))

    def entries(self, exclude=()) -> Iterator[tuple[int, int, int]]:
        """(channel, index, log time) in order, leaving out the channels in `exclude`."""
        channels, indices, times = self.channels, self.indices_, self.times
        if exclude:
            keep = ~np.isin(channels, list(exclude))
            channels, indices, times = channels[keep], indices[keep], times[keep]
        return zip(channels.tolist(), indices.tolist(), times.tolist())

    def indices(self, channel: int) -> list[int]:
        """The channel's messages (their indices in file order) in log time order."""
        return self.indices_[self.channels == channel].tolist()

    def times_by_index(self, channel: int) -> list[int]:
        """The log times of the channel's messages in file order."""
        mine = self.channels == channel
        out = np.empty(int(mine.sum()), dtype=self.times.dtype)
        out[self.indices_[mine]] = self.times[mine]
        return out.tolist()


@dataclass(frozen=True, slots=True)
class _Located:
    """Wanted messages of one or more chunks: per channel their bytes in file order, and their order."""

    per_channel: dict[int, list[bytes]]
    order: _Order

    @classmethod
    def join(cls, parts: list[_Located]) -> _Located:
        """Chunks that follow each other in time, as one: each channel's messages in chunk order."""
        if not parts:
            return cls({}, _Order.empty())
        if len(parts) == 1:
            return parts[0]
        per_channel: dict[int, list[bytes]] = {}
        orders = []
        for part in parts:
            orders.append(part.order.after({ch: len(per_channel.get(ch, ())) for ch in part.per_channel}))
            for ch, datas in part.per_channel.items():
                per_channel.setdefault(ch, []).extend(datas)
        return cls(per_channel, _Order.concat(orders))


@dataclass(frozen=True, slots=True)
class _Reading:
    """What one messages() call reads: decoders and topic names by channel, the log time window, the
    wanted channels and the tabled ones."""

    decoders: dict
    names: dict[int, str]
    lo: int
    hi: int
    wanted: frozenset
    tabled: dict[int, JointTable]

    def untabled(self) -> _Reading:
        return _Reading(self.decoders, self.names, self.lo, self.hi, self.wanted, {})


def _third(entry) -> int:
    return entry[2]


def _logged_time(msg: Logged) -> int:
    return msg.log_time_ns
