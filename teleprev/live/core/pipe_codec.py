"""The command sender's pipe messages as length-prefixed JSON: typed, and nothing is unpickled.

A message is a frozen dataclass of a known type (`types`: name -> class), a string, or a plain value;
numpy arrays, tuples and dicts (string keys) are tagged so that they come back as they went. Floats keep every bit:
JSON writes
a float's shortest repr, which reads back to the same double (-0.0 and non-finite values included), so a
session re-runs bit for bit whatever crossed the pipe.

    data = frame(TargetUpdate(...))                  # bytes to write
    messages, rest = unframe(buffer, types)          # the whole messages at the start of buffer
"""

from __future__ import annotations

import dataclasses
import json
import os
import struct

import numpy as np

_HEADER = struct.Struct("<I")


def types_by_name(*classes: type) -> dict[str, type]:
    return {cls.__name__: cls for cls in classes}


def frame(message) -> bytes:
    data = json.dumps(_encode(message), separators=(",", ":")).encode()
    return _HEADER.pack(len(data)) + data


def write_what_fits(fd: int, data: bytes) -> bytes:
    """Write as much of `data` as a non-blocking pipe takes now and return the rest (b"" once the reader
    is gone: nothing more can be delivered)."""
    while data:
        try:
            n = os.write(fd, data)
        except BlockingIOError:
            return data
        except BrokenPipeError:
            return b""
        data = data[n:]
    return data


def unframe(buffer: bytes, types: dict[str, type]) -> tuple[list, bytes]:
    """The whole messages at the start of `buffer`, and what is left of it. A message of a type not in
    `types` raises ValueError."""
    out = []
    while len(buffer) >= _HEADER.size:
        (size,) = _HEADER.unpack_from(buffer)
        if len(buffer) < _HEADER.size + size:
            break
        out.append(_decode(json.loads(buffer[_HEADER.size:_HEADER.size + size]), types))
        buffer = buffer[_HEADER.size + size:]
    return out, buffer


def _encode(value):
    if isinstance(value, np.ndarray):
        return {"nd": value.tolist(), "dtype": value.dtype.str}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple):
        return {"tuple": [_encode(v) for v in value]}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {"type": type(value).__name__,
                "fields": {f.name: _encode(getattr(value, f.name)) for f in dataclasses.fields(value)}}
    if isinstance(value, list):
        return [_encode(v) for v in value]
    if isinstance(value, dict):
        return {"dict": {str(k): _encode(v) for k, v in value.items()}}
    return value  # str, int, float, bool, None


def _decode(value, types: dict[str, type]):
    if isinstance(value, list):
        return [_decode(v, types) for v in value]
    if not isinstance(value, dict):
        return value
    if "nd" in value:
        return np.array(value["nd"], dtype=np.dtype(value["dtype"]))
    if "tuple" in value:
        return tuple(_decode(v, types) for v in value["tuple"])
    if "dict" in value:
        return {k: _decode(v, types) for k, v in value["dict"].items()}
    cls = types.get(value.get("type"))
    if cls is None:
        raise ValueError(f"the command sender's pipe carried a message of unknown type {value.get('type')!r}")
    return cls(**{k: _decode(v, types) for k, v in value["fields"].items()})
