"""One XR frame as the page sends it over the WebSocket: a binary message, little-endian, 1656 bytes.

    offset  type        field
    0       4 bytes     magic b"TPXR"
    4       u16         version (1)
    6       u8          present: bit 0 the headset, bit 1 the left hand, bit 2 the right hand
    7       u8          0
    8       u32         sequence number (the page counts every XR frame it sends, from 0)
    12      f64         frame time, ms on the page's clock (performance.timeOrigin + the XRFrame's time)
    20      f64         send time, ms on the page's clock
    28      f32 x 7     headset pose in the reference space: position (m), orientation (x y z w)
    56      f32 x 200   left hand: 25 joints (hands.JOINTS order) x position, orientation, radius
    856     f32 x 200   right hand, likewise
An absent part (an untracked hand) is sent as zeros with its bit clear. `pack` writes the same layout
(tests and benchmarks play a page with it); page/xr.js is the page's side.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

MAGIC = b"TPXR"
VERSION = 1
_HEAD = struct.Struct("<4sHBBIdd")
_FLOATS = 7 + 2 * 25 * 8
SIZE = _HEAD.size + 4 * _FLOATS
HEADSET, LEFT, RIGHT = 1, 2, 4


class WireError(ValueError):
    """A message that is not an XR frame of this version."""


@dataclass(frozen=True, slots=True)
class XrFrame:
    seq: int
    time_ms: float  # the page's clock
    sent_ms: float
    head: np.ndarray | None  # (7,) float64 of the float32 sent
    left: np.ndarray | None  # (25, 8)
    right: np.ndarray | None

    def hand(self, side: str) -> np.ndarray | None:
        return self.left if side == "left" else self.right


def unpack(data: bytes) -> XrFrame:
    if len(data) != SIZE:
        raise WireError(f"an XR frame is {SIZE} bytes, got {len(data)}")
    magic, version, present, _, seq, time_ms, sent_ms = _HEAD.unpack_from(data)
    if magic != MAGIC or version != VERSION:
        raise WireError(f"not a version-{VERSION} XR frame (magic {magic!r}, version {version})")
    values = np.frombuffer(data, dtype="<f4", offset=_HEAD.size).astype(float)
    if not (np.isfinite(time_ms) and np.isfinite(sent_ms)):
        raise WireError("the frame time is not a finite number")
    parts = (values[:7], values[7:207].reshape(25, 8), values[207:].reshape(25, 8))
    head, left, right = (p if present & bit else None for p, bit in zip(parts, (HEADSET, LEFT, RIGHT)))
    return XrFrame(seq, time_ms, sent_ms, head, left, right)


def pack(seq: int, time_ms: float, sent_ms: float, head=None, left=None, right=None) -> bytes:
    present = (
        (HEADSET if head is not None else 0) | (LEFT if left is not None else 0) | (RIGHT if right is not None else 0)
    )
    values = np.zeros(_FLOATS, dtype="<f4")
    for part, start, size in ((head, 0, 7), (left, 7, 200), (right, 207, 200)):
        if part is not None:
            values[start:start + size] = np.asarray(part, dtype=float).reshape(size)
    return _HEAD.pack(MAGIC, VERSION, present, 0, seq & 0xFFFFFFFF, time_ms, sent_ms) + values.tobytes()
