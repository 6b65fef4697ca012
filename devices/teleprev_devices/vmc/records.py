"""The records the VMC decoding process (devices/vmc/decoding_process.py) writes to its pipe: a fixed binary
layout, so that nothing is unpickled and doubles cross bit for bit. Each is a RECORD header (kind, body
length) and its body:
    STATUS    once, first: the process's scheduling as the receiver reports it ("SCHED_FIFO priority 5")
    COUNTERS  the decoder's counters (devices/vmc/decode.py: Counters), whenever a datagram changed them
    FRAME     a datagram's Frame: receive and stamp times on the session clock, then each bone it updated
              (its index in BONE_NAMES and 7 doubles: position, unit rotation); the receiver keeps the skeleton.
"""

from __future__ import annotations

import dataclasses
import struct

import numpy as np

from teleprev_devices.vmc.decode import BonePose, Counters, Frame
from teleprev_devices.vmc.unity import KNOWN_BONES

RECORD = struct.Struct("<BI")  # kind, body length
STATUS, COUNTERS, FRAME = 0, 1, 2
COUNTER_NAMES = tuple(f.name for f in dataclasses.fields(Counters))
COUNTER_VALUES = struct.Struct("<" + "Q" * len(COUNTER_NAMES))
FRAME_HEAD = struct.Struct("<qqH")  # receive_ns, stamp_ns, bones updated
FRAME_BONE = struct.Struct("<H7d")  # index in BONE_NAMES, position (3), rotation (4)
BONE_NAMES = ("", *sorted(KNOWN_BONES))  # "": the root
_BONE_INDEX = {name: i for i, name in enumerate(BONE_NAMES)}


def status_record(text: str) -> bytes:
    body = text.encode()
    return RECORD.pack(STATUS, len(body)) + body


def counters_record(counters: Counters) -> bytes:
    return RECORD.pack(COUNTERS, COUNTER_VALUES.size) + COUNTER_VALUES.pack(*dataclasses.astuple(counters))


def frame_record(frame: Frame) -> bytes:
    body = [FRAME_HEAD.pack(frame.receive_ns, frame.stamp_ns, len(frame.updated))]
    for name in frame.updated:
        pose = frame.bones[name]
        body.append(FRAME_BONE.pack(_BONE_INDEX[name], *pose.position, *pose.rotation))
    data = b"".join(body)
    return RECORD.pack(FRAME, len(data)) + data


@dataclasses.dataclass(frozen=True)
class Decoded:
    """A FRAME record read back: the bones the datagram updated (the receiver merges them into the skeleton)."""

    receive_ns: int
    stamp_ns: int
    updated: dict[str, BonePose]


def read_records(buffer: bytes) -> tuple[list[tuple[int, str | Counters | Decoded]], bytes]:
    """The whole records at the start of `buffer` as (kind, value), and what is left of it."""
    out = []
    at = 0
    while len(buffer) - at >= RECORD.size:
        kind, size = RECORD.unpack_from(buffer, at)
        start = at + RECORD.size
        if len(buffer) - start < size:
            break
        body = memoryview(buffer)[start:start + size]
        if kind == STATUS:
            out.append((kind, bytes(body).decode()))
        elif kind == COUNTERS:
            out.append((kind, Counters(*COUNTER_VALUES.unpack(body))))
        elif kind == FRAME:
            receive_ns, stamp_ns, n = FRAME_HEAD.unpack_from(body)
            updated = {}
            for k in range(n):
                index, *values = FRAME_BONE.unpack_from(body, FRAME_HEAD.size + k * FRAME_BONE.size)
                updated[BONE_NAMES[index]] = BonePose(_array(values[:3]), _array(values[3:]))
            out.append((kind, Decoded(receive_ns, stamp_ns, updated)))
        else:
            raise ValueError(f"the VMC decoding process wrote a record of unknown kind {kind}")
        at = start + size
    return out, buffer[at:]


def _array(values) -> np.ndarray:
    return np.array(values, dtype=float)
