"""Whether a session file still holds what was written: every chunk's CRC, compression and records, and
the CRC of the whole data section (message indexes and metadata included)."""

from __future__ import annotations

import struct

from teleprev.session import records as mr
from teleprev.session.chunk_file import ChunkFile


def data_section_intact(chunks: ChunkFile, file_bytes: int) -> bool | None:
    """Whether the bytes before the summary still match the CRC the writer stored in the data-end
    record (None when the file has none): reads the whole data section once."""
    try:
        _, summary_start, _ = mr.read_footer(chunks.f, file_bytes)
        end_at = (summary_start or file_bytes - mr.FOOTER_RECORD_SIZE - len(mr.MAGIC)) - 13  # DataEnd: 1+8+4
        op, length, crc = struct.unpack("<BQI", mr.read_exact(chunks.f, end_at, 13))
    except (mr.McapFormatError, struct.error):
        return None
    if op != mr.DATA_END or length != 4 or not crc:
        return None
    view = memoryview(chunks.mm)[:end_at]
    try:
        return mr.crc32(view) == crc
    finally:
        view.release()
        chunks.release_pages()


def damaged_chunks(chunks: ChunkFile, index: list[mr.ChunkIndex]) -> list[tuple[mr.ChunkIndex, str]]:
    """Every chunk of `index` that does not read back whole (CRC, compression, records), with why, in file
    order; reads the whole file once."""
    out = []
    for chunk in sorted(index, key=lambda c: c.offset):
        try:
            buf = chunks.read(chunk)
            for op, b, e in mr.iter_records(buf):
                if op == mr.MESSAGE and e - b < 22:
                    raise mr.McapFormatError("message record too short", b - 9)
        except mr.McapFormatError as exc:
            out.append((chunk, str(exc)))
        chunks.release_pages()
    return out
