"""Chunks decoded in batches: consecutive chunks that overlap no other, each channel's messages of all of
them decoded together (see JointStatesDecoder.batch), in log time order; tabled channels go to their
JointTables instead."""

from __future__ import annotations

from collections.abc import Iterator

from teleprev.errors import SessionError
from teleprev.messages import Logged
from teleprev.session import records as mr
from teleprev.session.chunk_file import ChunkFile
from teleprev.session.chunk_lookup import locate
from teleprev.session.message_selection import LocatedMessages, MessageOrder, ReadRequest

BATCH_CHUNKS = 8  # chunks decoded together at most (each channel's messages of them in one batch),
BATCH_BYTES = 8 << 20  # and their compressed bytes at most; release_pages after each batch


def batch_is_full(batch: list[mr.ChunkIndex]) -> bool:
    return len(batch) >= BATCH_CHUNKS or sum(c.length for c in batch) >= BATCH_BYTES


def decode_batch(file: ChunkFile, chunks: list[mr.ChunkIndex], request: ReadRequest) -> Iterator[Logged]:
    """Consecutive chunks that overlap no other, each channel's messages of all of them decoded in one
    batch; what decoding them chunk by chunk gives, errors included: a chunk that does not read is
    raised after the messages of the chunks before it, and a message that does not decode sends the
    batch back to chunk by chunk, which fails where it always did."""
    located, error = [], None
    for chunk in chunks:
        try:
            located.append(locate(file, chunk, request))
        except SessionError as exc:
            error = exc
            break
    try:
        messages = decode_located(file, LocatedMessages.join(located), request)
    except SessionError:
        for one in located:
            yield from decode_located(file, one, request)
    else:
        yield from messages
    if error is not None:
        raise error


def decode_chunk(file: ChunkFile, chunk: mr.ChunkIndex, request: ReadRequest) -> list[Logged]:
    return decode_located(file, locate(file, chunk, request), request)


def decode_located(file: ChunkFile, located: LocatedMessages, request: ReadRequest) -> list[Logged]:
    """The located messages decoded, in log time order (file order for equal times); those of tabled
    channels go to their tables instead, once every channel has decoded. Each channel's messages
    are decoded together (see JointStatesDecoder.batch)."""
    names = request.names
    order = located.order
    decoded, tabled = {}, []
    for ch, datas in located.per_channel.items():
        decoder, table = request.decoders[ch], request.tabled.get(ch)
        if table is None:
            decoded[ch] = _decode_all(file, decoder, getattr(decoder, "batch", None), datas, names[ch], ch, order)
        else:
            tabled.append((table, ch, _decode_all(file, decoder, decoder.columns, datas, names[ch], ch, order)))
    for table, ch, (stamps, positions) in tabled:
        table.extend_in_order(stamps, positions, order.indices(ch))
    return [Logged(names[c], t, decoded[c][k]) for c, k, t in order.entries(exclude=request.tabled)]


def _decode_all(file: ChunkFile, decoder, batch, datas: list[bytes], topic: str, channel: int,
                order: MessageOrder):
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
                               str(file.path)) from None
    raise SessionError(f"messages on {topic} do not decode", str(file.path))
