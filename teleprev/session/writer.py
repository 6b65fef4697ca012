"""Writes a session file: one MCAP, chunked and zstd-compressed, channels created on first use per topic.

Not thread-safe: one writer thread owns it (see recorder.py). `flush()` ends the open chunk and hands
the bytes to the OS (and fsyncs them by default), so a crash loses at most what came after the last
flush; `close()` writes the summary and index and makes the file complete.
"""

from __future__ import annotations

import datetime as _dt
import os
import time
from dataclasses import dataclass
from pathlib import Path

from teleprev import __version__
from teleprev.errors import SessionError
from teleprev.messages import Event, Logged, Payload
from teleprev.session.codec import channel_metadata, encode, schema_for
from teleprev.topics import FORMAT_VERSION

DEFAULT_CHUNK_SIZE = 4 * 1024 * 1024
TELEPREV_RECORD = "teleprev"  # metadata record written at open: format and software versions


@dataclass(slots=True)
class _Channel:
    id: int
    payload_type: type
    schema: str
    metadata: dict[str, str]  # codec.channel_metadata of its first payload (a depth channel's unit)
    sequence: int = 0


def check_metadata(name: str, data: dict[str, str]) -> dict[str, str]:
    """MCAP metadata is a map of strings to strings; say which key is wrong otherwise."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"metadata record name must be a non-empty string, got {name!r}")
    if not isinstance(data, dict):
        raise ValueError(f"metadata record {name!r} must be a dict of strings, got {type(data).__name__}")
    for k, v in data.items():
        if not isinstance(k, str) or not isinstance(v, str):
            raise ValueError(f"metadata record {name!r}: key {k!r} -> {v!r} is not a string -> string pair")
    return dict(data)


class McapSessionWriter:
    def __init__(
        self,
        path: str | os.PathLike,
        metadata: dict[str, dict[str, str]] | None = None,
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: str = "zstd",
        fsync: bool = True,
        attachments: dict[str, tuple[str, bytes]] | None = None,
    ):
        """`attachments`: name -> (media type, bytes), written at the start (the robot's URDF)."""
        from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

        kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in kinds:
            raise ValueError(f"compression must be one of {', '.join(kinds)}, got {compression!r}")
        metadata = dict(metadata or {})
        if TELEPREV_RECORD in metadata:
            raise ValueError(f"metadata record name {TELEPREV_RECORD!r} is reserved for the writer")
        records = {name: check_metadata(name, rec) for name, rec in metadata.items()}

        self.path = Path(path)
        try:
            self._file = open(self.path, "xb")  # never overwrite a recording
        except FileExistsError:
            raise SessionError("already exists; teleprev does not overwrite a recording", str(self.path)) from None
        except OSError as exc:
            raise SessionError(f"cannot create the session file: {exc.strerror}", str(self.path)) from None
        self._fsync = fsync
        self.flushed_bytes = 0  # file size after the last successful flush: what abort() keeps
        # enable_data_crcs: the data section's CRC goes in the file's end, so `teleprev info` can tell a
        # changed byte anywhere before the summary, not only inside a chunk
        self._mcap = Writer(self._file, chunk_size=chunk_size, compression=kinds[compression], enable_data_crcs=True)
        self._mcap.start(profile="", library=f"teleprev/{__version__} {LIBRARY_IDENTIFIER}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, _Channel] = {}
        self.closed = False
        now = time.time_ns()
        self.add_metadata(TELEPREV_RECORD, {
            "format_version": str(FORMAT_VERSION),
            "software_version": __version__,
            "created_ns": str(now),
            "created": _dt.datetime.fromtimestamp(now / 1e9, _dt.UTC).isoformat(timespec="milliseconds"),
        })
        for name, rec in records.items():
            self.add_metadata(name, rec)
        for name, (media_type, data) in (attachments or {}).items():
            self._mcap.add_attachment(now, now, name, media_type, bytes(data))
        self.flush()

    def _channel(self, topic: str, payload: Payload) -> _Channel:
        spec = schema_for(payload)
        schema_id = self._schemas.get(spec.name)
        if schema_id is None:
            schema_id = self._schemas[spec.name] = self._mcap.register_schema(spec.name, spec.encoding, spec.data)
        metadata = channel_metadata(payload)
        cid = self._mcap.register_channel(topic, spec.message_encoding, schema_id, metadata)
        ch = self._channels[topic] = _Channel(cid, type(payload), spec.name, metadata)
        return ch

    def write(self, msg: Logged) -> int:
        """Encode and add one message; returns its encoded size. Raises ValueError/TypeError for a
        payload that cannot be recorded on its topic (nothing is written then)."""
        payload = msg.payload
        ch = self._channels.get(msg.topic)
        if ch is None:
            ch = self._channel(msg.topic, payload)
        elif type(payload) is not ch.payload_type or (type(payload) is Event and payload.schema != ch.schema):
            got = payload.schema if isinstance(payload, Event) else type(payload).__name__
            raise ValueError(f"topic {msg.topic} carries {ch.schema}; cannot also record {got} on it")
        elif ch.metadata and (ch.metadata != channel_metadata(payload) or schema_for(payload).name != ch.schema):
            raise ValueError(f"topic {msg.topic} carries {ch.schema} {ch.metadata}; cannot also record "
                             f"{schema_for(payload).name} {channel_metadata(payload)} on it")
        log_time = msg.log_time_ns
        if type(log_time) is not int:
            log_time = int(log_time)
        if log_time < 0:
            raise ValueError(f"topic {msg.topic}: negative log_time_ns {log_time}")
        data = encode(payload)
        self._mcap.add_message(ch.id, log_time, data, log_time, ch.sequence)
        ch.sequence = (ch.sequence + 1) & 0xFFFFFFFF
        return len(data)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record (written at once between chunks; the open chunk stays open)."""
        self._mcap.add_metadata(name, check_metadata(name, data))

    def flush(self) -> None:
        """End the open chunk and push everything to the OS (and to the disk when fsync is on)."""
        self._mcap.flush()
        self._file.flush()
        if self._fsync:
            os.fsync(self._file.fileno())
        self.flushed_bytes = self._file.tell()

    def close(self) -> None:
        """Write the summary and index (a complete MCAP) and close the file."""
        if self.closed:
            return
        self.closed = True
        try:
            self._mcap.finish()
            self._file.flush()
            if self._fsync:
                os.fsync(self._file.fileno())
        finally:
            self._file.close()

    def abort(self) -> None:
        """Close the file without a summary, after an I/O error: what was flushed stays on disk for
        `teleprev recover`, and a record the error cut in half is taken off the end (which also gives
        the space back on a full disk)."""
        if self.closed:
            return
        self.closed = True
        try:
            self._file.close()
        except OSError:
            pass
        try:
            if self.flushed_bytes and self.path.stat().st_size > self.flushed_bytes:
                os.truncate(self.path, self.flushed_bytes)
        except OSError:
            pass

    def __enter__(self) -> McapSessionWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
