"""The summary of a complete MCAP file written without one (or without chunk indexes), found by reading
the file through once."""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

from teleprev.errors import SessionError
from teleprev.session import records as mr


def index_by_scan(f: BinaryIO, file_bytes: int, path: Path) -> mr.SummarySection:
    """Index a complete MCAP written without a summary by reading it through once."""
    out = mr.SummarySection()
    counts: dict[int, int] = {}
    scan = mr.Scan(f, file_bytes)
    for offset, op, body in scan.records():
        try:
            if op == mr.CHUNK:
                chunk = mr.parse_chunk(body, 0, len(body))
                buf = mr.decompress(chunk)
                for iop, b, e in mr.iter_records(buf):
                    if iop == mr.SCHEMA:
                        s = mr.parse_schema(buf, b, e)
                        out.schemas[s.id] = s
                    elif iop == mr.CHANNEL:
                        c = mr.parse_channel(buf, b, e)
                        out.channels[c.id] = c
                    elif iop == mr.MESSAGE:
                        cid = mr._U16.unpack_from(buf, b)[0]
                        counts[cid] = counts.get(cid, 0) + 1
                out.chunks.append(mr.ChunkIndex(chunk.start_ns, chunk.end_ns, offset, 9 + len(body), {}, 0,
                                                chunk.compression))
            elif op == mr.SCHEMA:
                s = mr.parse_schema(body, 0, len(body))
                out.schemas[s.id] = s
            elif op == mr.CHANNEL:
                c = mr.parse_channel(body, 0, len(body))
                out.channels[c.id] = c
            elif op == mr.MESSAGE:
                raise SessionError("messages outside chunks are not supported; run `teleprev recover` on it "
                                   "to rewrite it chunked", str(path))
            elif op == mr.METADATA:
                out.metadata.append((mr.parse_metadata(body, 0, len(body))[0], offset, 9 + len(body)))
        except mr.McapFormatError as exc:
            raise SessionError(f"record at byte {offset} is damaged: {exc}", str(path)) from None
    if scan.stop != "footer":
        raise SessionError(f"the file is cut short ({scan.stop}); run `teleprev recover {path}`", str(path))
    out.statistics = mr.Statistics(sum(counts.values()), len(out.schemas), len(out.channels), 0,
                                   len(out.metadata), len(out.chunks), 0, 0, counts)
    return out
