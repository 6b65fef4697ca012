"""A session's messages in log time order (file order for equal times): chunks that overlap no other are
decoded in batches of consecutive chunks, chunks that overlap in time are merged, and the file's pages
are released after each, so memory stays bounded by a few chunks."""

from __future__ import annotations

from collections.abc import Iterator

from teleprev.messages import Logged
from teleprev.session import records as mr
from teleprev.session.chunk_batches import batch_is_full, decode_batch, decode_chunk
from teleprev.session.chunk_file import ChunkFile
from teleprev.session.chunk_lookup import chunk_groups
from teleprev.session.message_selection import ReadRequest


def ordered_messages(file: ChunkFile, chunks: list[mr.ChunkIndex], request: ReadRequest) -> Iterator[Logged]:
    """The wanted messages of `chunks` (sorted by start time) in [request.lo, request.hi), decoded."""
    batch: list[mr.ChunkIndex] = []  # consecutive chunks that overlap no other: decoded together
    for group in chunk_groups(chunks, request.lo, request.hi, request.wanted):
        if len(group) == 1:
            batch.append(group[0])
            if not batch_is_full(batch):
                continue
            yield from decode_batch(file, batch, request)
        else:
            if batch:
                yield from decode_batch(file, batch, request)
            yield from _merged(file, group, request)
        batch = []
        file.release_pages()
    if batch:
        yield from decode_batch(file, batch, request)


def _merged(file: ChunkFile, group: list[mr.ChunkIndex], request: ReadRequest) -> Iterator[Logged]:
    """Chunks overlapping in time: merged (a stable sort keeps file order for equal times). Tabled topics
    are decoded as messages here too, then appended to their tables in the merged order."""
    merged = [m for c in sorted(group, key=lambda c: c.offset)
              for m in decode_chunk(file, c, request.untabled())]
    merged.sort(key=_logged_time)
    by_topic = {request.names[ch]: table for ch, table in request.tabled.items()}
    for m in merged:
        table = by_topic.get(m.topic)
        if table is None:
            yield m
        else:
            table.append(m.payload.stamp_ns, m.payload.positions)


def _logged_time(msg: Logged) -> int:
    return msg.log_time_ns
