"""Where the wanted messages are: which chunks may hold a log time window's messages (in time order,
grouped where chunks overlap), and a chunk's wanted messages found through its message index (or, without
a usable one, record by record)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from teleprev.session import records as mr
from teleprev.session.chunk_file import ChunkFile
from teleprev.session.message_selection import LocatedMessages, MessageOrder, ReadRequest

_I64_END = (1 << 63) - 1  # log times beyond int64 (year 2262) are not expected
_HEAD_BYTES = np.arange(23)  # a message record's opcode, length, channel, sequence and log time


def chunk_groups(chunks: list[mr.ChunkIndex], lo: int, hi: int, wanted) -> Iterator[list[mr.ChunkIndex]]:
    """The chunks (sorted by start time) that may hold wanted messages in [lo, hi), in time order, as groups
    of chunks that overlap in time (most groups are one chunk)."""
    group: list = []
    group_end = -1
    for chunk in chunks:
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


def locate(file: ChunkFile, chunk: mr.ChunkIndex, request: ReadRequest) -> LocatedMessages:
    """The chunk's messages on wanted channels in [lo, hi), as bytes, and their order."""
    buf = file.records(chunk)
    located = _locate_indexed(file, chunk, buf, request.wanted, request.lo, request.hi)
    if located is None:
        located = _locate_sequential(file, chunk, buf, request.wanted, request.lo, request.hi)
    return LocatedMessages(*located)


def _locate_indexed(file: ChunkFile, chunk, buf: bytes, wanted, lo: int, hi: int):
    """Per channel, the wanted messages' bytes, and the (channel, index, log time) order, found
    through the message index with numpy; None when the chunk has no usable index (then the chunk
    is parsed record by record). Every index entry is checked against the record it points at."""
    index = file.message_index(chunk)
    if index is None:
        return None
    sel = [(ch, e) for ch, e in index.items() if ch in wanted]
    if not sel:
        return {}, MessageOrder.empty()
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
    return per_channel, MessageOrder(chans[ordering], ks[ordering], times[ordering])


def _locate_sequential(file: ChunkFile, chunk, buf: bytes, wanted, lo: int, hi: int):
    per_channel: dict[int, list[bytes]] = {}
    order: list[tuple[int, int, int]] = []  # (channel, index in that channel's list, log time)
    head = mr.MESSAGE_HEADER.unpack_from
    for op, b, e in file.iter_records(chunk, buf):
        if op == mr.MESSAGE:
            ch, _seq, t, _pub = head(buf, b)
            if ch in wanted and lo <= t < hi:
                datas = per_channel.get(ch)
                if datas is None:
                    datas = per_channel[ch] = []
                order.append((ch, len(datas), t))
                datas.append(buf[b + 22:e])
    order.sort(key=_third)  # stable: file order for equal times
    return per_channel, MessageOrder.of(order)


def _third(entry) -> int:
    return entry[2]
