"""foxglove protobuf messages read straight from their wire format: varints, the Timestamp, and the
full parses of foxglove.PoseInFrame and foxglove.JointStates that codec's decoders fall back on (and
learn their fast byte layouts from). Our own parser rather than the protobuf runtime's, whose import
costs ~40 ms, a tenth of a short eval."""

from __future__ import annotations

import math
import struct

import numpy as np

from teleprev.messages import PoseSample

_NS = 1_000_000_000
_F64 = np.dtype("<f8")
_DOUBLE = struct.Struct("<d")


def _varint(buf: bytes, pos: int) -> tuple[int, int]:
    result = shift = 0
    while True:
        b = buf[pos]
        pos += 1
        result |= (b & 0x7F) << shift
        if b < 0x80:
            return result, pos
        shift += 7
        if shift > 63:
            raise ValueError("malformed varint")


def _skip(buf: bytes, pos: int, wire: int) -> int:
    if wire == 0:
        return _varint(buf, pos)[1]
    if wire == 1:
        return pos + 8
    if wire == 2:
        n, pos = _varint(buf, pos)
        return pos + n
    if wire == 5:
        return pos + 4
    raise ValueError(f"unsupported protobuf wire type {wire}")


def _uvarint5(b: bytes, p: int) -> tuple[int, int]:
    """An unsigned varint of at most 5 bytes (a timestamp field); (-1, p) for a longer one."""
    x = b[p]
    if x < 0x80:
        return x, p + 1
    r = x & 0x7F
    x = b[p + 1]
    r |= (x & 0x7F) << 7
    if x < 0x80:
        return r, p + 2
    x = b[p + 2]
    r |= (x & 0x7F) << 14
    if x < 0x80:
        return r, p + 3
    x = b[p + 3]
    r |= (x & 0x7F) << 21
    if x < 0x80:
        return r, p + 4
    x = b[p + 4]
    r |= (x & 0x7F) << 28
    if x < 0x80:
        return r, p + 5
    return -1, p


def _parse_timestamp(buf: bytes, pos: int, end: int) -> int:
    sec = nsec = 0
    while pos < end:
        tag, pos = _varint(buf, pos)
        if tag == 0x08:
            sec, pos = _varint(buf, pos)
            if sec >= 1 << 63:
                sec -= 1 << 64
        elif tag == 0x10:
            nsec, pos = _varint(buf, pos)
            if nsec >= 1 << 63:
                nsec -= 1 << 64
        else:
            pos = _skip(buf, pos, tag & 7)
    if pos != end:
        raise ValueError("malformed timestamp")
    return sec * _NS + nsec


def _timestamp_spans(data: bytes) -> tuple[tuple[int, int], tuple[int, int]] | None:
    """Where the seconds and nanos varints of a leading timestamp field are, if each is at most 5 bytes
    (so a stamp fits the fast paths); None otherwise."""
    if len(data) < 2 or data[0] != 0x0A or data[1] >= 0x80:
        return None
    end = 2 + data[1]
    p = 2
    spans = [(p, 0), (p, 0)]
    for which, tag in ((0, 0x08), (1, 0x10)):
        if p < end and data[p] == tag:
            value, q = _uvarint5(data, p + 1)
            if value < 0:
                return None
            spans[which] = (p + 1, q - p - 1)
            p = q
    if p != end:
        return None
    return spans[0], spans[1]


def _length_fields(data: bytes, pos: int, end: int, wanted: tuple[int, ...]):
    """(field, start, stop) of each length-delimited field numbered in `wanted` in data[pos:end], in
    order; other fields are skipped. ValueError where a field runs past `end`."""
    while pos < end:
        tag, pos = _varint(data, pos)
        field, wire = tag >> 3, tag & 7
        if wire != 2 or field not in wanted:
            pos = _skip(data, pos, wire)
            continue
        length, pos = _varint(data, pos)
        if pos + length > end:
            raise ValueError("a field runs past its message")
        yield field, pos, pos + length
        pos += length
    if pos != end:
        raise ValueError("a field runs past its message")


def _parse_doubles(data: bytes, pos: int, end: int, values: list[float], base: int, count: int) -> None:
    """A message of doubles numbered 1..count (Vector3, Quaternion) into values[base:base + count]."""
    while pos < end:
        tag, pos = _varint(data, pos)
        field, wire = tag >> 3, tag & 7
        if wire == 1 and 1 <= field <= count:
            if pos + 8 > end:
                raise ValueError("a double runs past its message")
            values[base + field - 1] = _DOUBLE.unpack_from(data, pos)[0]
            pos += 8
        else:
            pos = _skip(data, pos, wire)
    if pos != end:
        raise ValueError("a field runs past its message")


def _parse_pose_in_frame(data: bytes) -> PoseSample:
    """foxglove.PoseInFrame's full wire-format parse, as the protobuf runtime reads it: absent fields
    zero, the last of a repeated value kept, a repeated pose merged into the one before. Our own parser
    rather than the runtime's, because importing the runtime costs ~40 ms, a tenth of a short eval."""
    stamp, frame_id = 0, ""
    values = [0.0] * 7  # position x y z, orientation x y z w
    for field, start, stop in _length_fields(data, 0, len(data), (1, 2, 3)):
        if field == 1:
            stamp = _parse_timestamp(data, start, stop)
        elif field == 2:
            frame_id = data[start:stop].decode("utf-8")
        else:  # the pose: position (Vector3 x y z) at 0-2, orientation (Quaternion x y z w) at 3-6
            for part, p0, p1 in _length_fields(data, start, stop, (1, 2)):
                _parse_doubles(data, p0, p1, values, *((0, 3) if part == 1 else (3, 4)))
    return PoseSample(stamp, frame_id, np.array(values[:3]), np.array(values[3:]))


def _parse_joint_states(data: bytes):
    """Full parse. Returns stamp, names, positions (NaN where absent), velocities (None when no joint has
    one), the byte offsets of the position / velocity doubles, and whether the message has the plain
    layout the fast path can learn (one timestamp, first; each joint exactly name + position
    [+ velocity]; velocities on all joints or none)."""
    n = len(data)
    pos = 0
    stamp = 0
    timestamp_first = False
    stamps_seen = 0
    names: list[str] = []
    positions: list[float] = []
    velocities: list[float] = []
    pos_off: list[int] = []
    vel_off: list[int] = []
    plain = True
    seen_joint = False
    nan = math.nan
    while pos < n:
        tag, pos = _varint(data, pos)
        field, wire = tag >> 3, tag & 7
        if field == 1 and wire == 2:
            ln, pos = _varint(data, pos)
            stamp = _parse_timestamp(data, pos, pos + ln)
            pos += ln
            stamps_seen += 1
            timestamp_first = not seen_joint
        elif field == 2 and wire == 2:
            seen_joint = True
            ln, pos = _varint(data, pos)
            end = pos + ln
            name, p, v, po, vo = "", nan, None, None, None
            while pos < end:
                t, pos = _varint(data, pos)
                f, w = t >> 3, t & 7
                if f == 1 and w == 2:
                    sl, pos = _varint(data, pos)
                    name = data[pos:pos + sl].decode("utf-8")
                    pos += sl
                elif f == 2 and w == 1:
                    po = pos
                    p = float(np.frombuffer(data, _F64, 1, pos)[0])
                    pos += 8
                elif f == 3 and w == 1:
                    vo = pos
                    v = float(np.frombuffer(data, _F64, 1, pos)[0])
                    pos += 8
                else:
                    pos = _skip(data, pos, w)
                    plain = False
            if pos != end:
                raise ValueError("malformed joint entry")
            names.append(name)
            positions.append(p)
            velocities.append(nan if v is None else v)
            pos_off.append(-1 if po is None else po)
            vel_off.append(-1 if vo is None else vo)
            if po is None or not name:
                plain = False
        else:
            pos = _skip(data, pos, wire)
            plain = False
    if pos != n:
        raise ValueError("truncated JointStates message")
    has_vel = [o >= 0 for o in vel_off]
    any_vel = any(has_vel)
    if any_vel and not all(has_vel):
        plain = False
    return (stamp, names, positions, velocities if any_vel else None, pos_off, vel_off if any_vel else None,
            plain and timestamp_first and stamps_seen == 1)
