"""Payloads to MCAP message bytes and back: foxglove protobuf schemas for samples, titled JSON for events,
and ROS 2 std_msgs/String in CDR for the robot description (the schema Foxglove's URDF layer reads).

Encoding uses the foxglove-sdk message classes. Decoding reads the schema stored in the file (protobuf
FileDescriptorSet or JSON schema); foxglove.JointStates and PoseInFrame, the streams eval reads, have
wire-format parsers of their own instead (protobuf_wire.py), and a fast path, JointStates being the bulk
of a session: a channel's messages share one byte layout apart from the timestamp and the float64
values, so once a layout is seen, a message is checked against it and its doubles are gathered with
numpy (a few µs for 45 joints instead of ~30 µs through the protobuf runtime). Anything that does not
match the layout exactly goes through a full wire-format parse, so the fast path never changes a result.

Depth (DepthSample) is recorded as foxglove.RawImage 16UC1, or as a 16-bit PNG in foxglove.CompressedImage: the
form each DepthSample names. Neither message has room for the depth unit, so the channel carries it in its
metadata ("depth_scale_m", metres per unit: channel_metadata()); a reader gives the channel's messages back as
DepthSamples with that scale (decoder_for's channel_metadata). A RawImage 16UC1 without it (a file teleprev did
not write) is read in millimetres, the ROS convention.

Event JSON carries the payload's `stamp_ns` as an extra "stamp_ns" property (the schemas in
topics.EVENT_SCHEMAS allow additional properties), so `data` must not use that key.

Caveat: foxglove.Vector3 / Quaternion fields have implicit presence, so a pose or transform component
of -0.0 reads back as +0.0. Joint values (explicit presence) and everything else round-trip bit-exactly.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from itertools import repeat

import numpy as np

from teleprev.messages import (
    CameraInfo,
    DepthSample,
    Event,
    ImageSample,
    JointSample,
    Payload,
    PoseSample,
    RobotDescription,
    Transform,
    TransformsSample,
)
from teleprev.session.protobuf_wire import _parse_joint_states, _parse_pose_in_frame, _timestamp_spans
from teleprev.topics import EVENT_SCHEMAS

JOINT_STATES = "foxglove.JointStates"
POSE_IN_FRAME = "foxglove.PoseInFrame"
COMPRESSED_IMAGE = "foxglove.CompressedImage"
FRAME_TRANSFORMS = "foxglove.FrameTransforms"
RAW_IMAGE = "foxglove.RawImage"
CAMERA_CALIBRATION = "foxglove.CameraCalibration"
DEPTH_SCALE_KEY = "depth_scale_m"  # channel metadata of a depth channel: metres per unit of its 16-bit values
DEPTH_FORMATS = ("raw", "png")
_ROS_DEPTH_SCALE = 0.001  # sensor_msgs/Image 16UC1 is millimetres
ROS_STRING = ("std_msgs/msg/String", "ros2msg", b"string data", "cdr")
_CDR_LE = b"\x00\x01\x00\x00"  # CDR encapsulation header: plain CDR, little endian
STAMP_KEY = "stamp_ns"

_NS = 1_000_000_000


@dataclass(frozen=True, slots=True)
class SchemaSpec:
    """What a channel needs: schema name, schema encoding and data, and the message encoding."""

    name: str
    encoding: str
    data: bytes
    message_encoding: str


_FOXGLOVE_CLASS = {
    JointSample: "JointStates",
    PoseSample: "PoseInFrame",
    ImageSample: "CompressedImage",
    TransformsSample: "FrameTransforms",
    CameraInfo: "CameraCalibration",
}
_spec_cache: dict[str, SchemaSpec] = {}


def schema_for(payload: Payload) -> SchemaSpec:
    """The schema a payload is recorded with (foxglove.* protobuf, or the event's titled JSON schema)."""
    if isinstance(payload, RobotDescription):
        return SchemaSpec(*ROS_STRING)
    if isinstance(payload, Event):
        key = payload.schema
        if key not in _spec_cache:
            if key not in EVENT_SCHEMAS:
                raise ValueError(f"unknown event schema {key!r} (known: {', '.join(EVENT_SCHEMAS)})")
            content = json.dumps(EVENT_SCHEMAS[key], sort_keys=True).encode()
            _spec_cache[key] = SchemaSpec(key, "jsonschema", content, "json")
        return _spec_cache[key]
    if isinstance(payload, DepthSample):
        cls_name = "RawImage" if payload.format == "raw" else "CompressedImage"
    else:
        cls_name = _FOXGLOVE_CLASS.get(type(payload))
    if cls_name is None:
        raise TypeError(f"cannot record a {type(payload).__name__} (expected one of the payloads in teleprev.messages)")
    if cls_name not in _spec_cache:
        import foxglove.messages as fm

        schema = getattr(fm, cls_name).get_schema()
        _spec_cache[cls_name] = SchemaSpec(schema.name, schema.encoding, bytes(schema.data), "protobuf")
    return _spec_cache[cls_name]


def channel_metadata(payload: Payload) -> dict[str, str]:
    """What a channel records beside its schema for this payload's stream: a depth channel's unit."""
    if isinstance(payload, DepthSample):
        return {DEPTH_SCALE_KEY: repr(float(payload.scale_m))}
    return {}


# --- encoding ------------------------------------------------------------------------------------


def _fm():
    import foxglove.messages as fm

    return fm


def _timestamp(fm, stamp_ns: int):
    stamp_ns = int(stamp_ns)
    if stamp_ns < 0:
        raise ValueError(f"negative stamp_ns {stamp_ns}")
    return fm.Timestamp(sec=stamp_ns // _NS, nsec=stamp_ns % _NS)


def _floats(values, n: int, what: str) -> list[float]:
    """Exactly n float64 values as Python floats (float32 input widens exactly)."""
    if type(values) is np.ndarray and values.ndim == 1 and values.dtype == np.float64:
        out = values.tolist()
    else:
        out = np.asarray(values, dtype=np.float64).reshape(-1).tolist()
    if len(out) != n:
        raise ValueError(f"{what} has {len(out)} values, expected {n}")
    return out


def _vec3(fm, v):
    x, y, z = _floats(v, 3, "translation/position")
    return fm.Vector3(x=x, y=y, z=z)


def _quat(fm, q):
    x, y, z, w = _floats(q, 4, "rotation/orientation")
    return fm.Quaternion(x=x, y=y, z=z, w=w)


def encode(payload: Payload) -> bytes:
    """The message bytes of a payload, in the encoding schema_for(payload) names."""
    fm = _fm()
    t = type(payload)
    if t is JointSample:
        names = payload.names
        pos = _floats(payload.positions, len(names), "positions")
        js = fm.JointState
        if payload.velocities is None:
            joints = [js(name=n, position=p) for n, p in zip(names, pos)]
        else:
            vel = _floats(payload.velocities, len(names), "velocities")
            joints = [js(name=n, position=p, velocity=v) for n, p, v in zip(names, pos, vel)]
        return fm.JointStates(timestamp=_timestamp(fm, payload.stamp_ns), joints=joints).encode()
    if t is ImageSample:
        return fm.CompressedImage(
            timestamp=_timestamp(fm, payload.stamp_ns), frame_id=payload.frame_id, data=bytes(payload.data),
            format=payload.format,
        ).encode()
    if t is DepthSample:
        return _encode_depth(fm, payload)
    if t is CameraInfo:
        if len(payload.k) != 9:
            raise ValueError(f"camera info {payload.frame_id!r}: k has {len(payload.k)} values, expected 9")
        fx, _, cx, _, fy, cy = payload.k[:6]
        return fm.CameraCalibration(
            timestamp=_timestamp(fm, payload.stamp_ns), frame_id=payload.frame_id, width=int(payload.width),
            height=int(payload.height), distortion_model=payload.distortion_model, D=[float(v) for v in payload.d],
            K=[float(v) for v in payload.k], R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            P=[float(fx), 0.0, float(cx), 0.0, 0.0, float(fy), float(cy), 0.0, 0.0, 0.0, 1.0, 0.0],
        ).encode()
    if t is PoseSample:
        pose = fm.Pose(position=_vec3(fm, payload.position), orientation=_quat(fm, payload.orientation))
        return fm.PoseInFrame(timestamp=_timestamp(fm, payload.stamp_ns), frame_id=payload.frame_id, pose=pose).encode()
    if t is TransformsSample:
        ts = _timestamp(fm, payload.stamp_ns)
        return fm.FrameTransforms(transforms=[
            fm.FrameTransform(timestamp=ts, parent_frame_id=tr.parent, child_frame_id=tr.child,
                              translation=_vec3(fm, tr.translation), rotation=_quat(fm, tr.rotation))
            for tr in payload.transforms
        ]).encode()
    if t is RobotDescription:
        text = payload.urdf.encode("utf-8") + b"\0"
        return _CDR_LE + len(text).to_bytes(4, "little") + text
    if t is Event:
        if STAMP_KEY in payload.data:
            raise ValueError(f"event data may not use the reserved key {STAMP_KEY!r}")
        return json.dumps({**payload.data, STAMP_KEY: int(payload.stamp_ns)}, separators=(",", ":")).encode()
    schema_for(payload)  # raises the TypeError naming the type
    raise AssertionError("unreachable")


def _encode_depth(fm, payload: DepthSample) -> bytes:
    depth = payload.depth
    if depth.dtype != np.uint16 or depth.ndim != 2:
        raise ValueError(f"depth {payload.frame_id!r}: expected an (H, W) uint16 image, got {depth.dtype} "
                         f"{depth.shape}")
    if not (payload.scale_m > 0 and np.isfinite(payload.scale_m)):
        raise ValueError(f"depth {payload.frame_id!r}: scale_m must be > 0, got {payload.scale_m}")
    stamp = _timestamp(fm, payload.stamp_ns)
    h, w = depth.shape
    if payload.format == "raw":
        data = depth.astype("<u2", copy=False).tobytes()
        return fm.RawImage(timestamp=stamp, frame_id=payload.frame_id, width=w, height=h, encoding="16UC1",
                           step=2 * w, data=data).encode()
    if payload.format == "png":
        import cv2

        # Level 1: a higher level saves ~2% of the size for 1.6x the time (bench/depth.py).
        ok, png = cv2.imencode(".png", depth, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise ValueError(f"depth {payload.frame_id!r}: PNG encoding failed")
        return fm.CompressedImage(timestamp=stamp, frame_id=payload.frame_id, data=png.tobytes(), format="png").encode()
    raise ValueError(f"depth {payload.frame_id!r}: format must be one of {', '.join(DEPTH_FORMATS)}, got "
                     f"{payload.format!r}")


# --- decoding ------------------------------------------------------------------------------------

Decoder = Callable[[bytes], Payload]


def decoder_for(schema_name: str, schema_encoding: str, schema_data: bytes, message_encoding: str,
                channel_metadata: dict[str, str] | None = None) -> Decoder:
    """A function from message bytes to a payload, for a channel with this schema (and, for depth, the
    channel's metadata). Raises ValueError for a schema teleprev does not read."""
    if (schema_name, message_encoding) == (ROS_STRING[0], ROS_STRING[3]):
        return _robot_description
    if message_encoding == "json":
        title = schema_name
        if schema_encoding == "jsonschema" and schema_data:
            try:
                title = json.loads(schema_data).get("title", schema_name)
            except (ValueError, AttributeError):
                pass
        return _EventDecoder(title)
    if message_encoding != "protobuf" or schema_encoding != "protobuf":
        raise ValueError(f"unsupported message encoding {message_encoding!r} / schema encoding {schema_encoding!r}")
    if schema_name == JOINT_STATES:
        return JointStatesDecoder()
    if schema_name == POSE_IN_FRAME:
        return PoseInFrameDecoder(_parse_pose_in_frame)
    scale = _depth_scale(channel_metadata)
    cls = _protobuf_class(schema_name, schema_data)
    if schema_name == COMPRESSED_IMAGE:
        return _image_decoder(cls) if scale is None else _png_depth_decoder(cls, scale)
    if schema_name == RAW_IMAGE:
        return _raw_depth_decoder(cls, _ROS_DEPTH_SCALE if scale is None else scale)
    if schema_name == CAMERA_CALIBRATION:
        return _calibration_decoder(cls)
    if schema_name == FRAME_TRANSFORMS:
        return _transforms_decoder(cls)
    raise ValueError(f"unsupported schema {schema_name!r}")


def _robot_description(data: bytes) -> RobotDescription:
    if len(data) < 9 or data[:4] != _CDR_LE:
        raise ValueError("not a little-endian CDR std_msgs/String")
    n = int.from_bytes(data[4:8], "little")
    if n < 1 or 8 + n > len(data):
        raise ValueError("string length runs past the message")
    return RobotDescription(0, data[8:8 + n - 1].decode("utf-8"))


class _EventDecoder:
    __slots__ = ("title",)

    def __init__(self, title: str):
        self.title = title

    def __call__(self, data: bytes) -> Event:
        obj = _json_loads(data)
        if not isinstance(obj, dict):
            raise ValueError("event JSON is not an object")
        stamp = obj.pop(STAMP_KEY, 0)
        return Event(int(stamp), self.title, obj)


_JSON = json.JSONDecoder()


def _json_loads(data: bytes):
    """json.loads(data), half its cost (~1.4 of 2.8 us per command tick) for what MCAP's JSON messages
    are: a UTF-8 object, nothing before or after it. json.loads of bytes first guesses their encoding
    among UTF-8, -16 and -32; an object starting and ending with braces that decodes as UTF-8 and scans
    to its last byte is read the same way, and anything else goes to json.loads itself."""
    if data[:1] == b"{" and data[-1:] == b"}":
        try:
            text = data.decode("utf-8")
            obj, end = _JSON.raw_decode(text)
        except ValueError:
            pass
        else:
            if end == len(text):
                return obj
    return json.loads(data)


_class_cache: dict[tuple[str, bytes], type] = {}


def _protobuf_class(name: str, fds_bytes: bytes) -> type:
    """The protobuf message class for `name`, built from the FileDescriptorSet stored in the file."""
    key = (name, fds_bytes)
    if key not in _class_cache:
        from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

        fds = descriptor_pb2.FileDescriptorSet.FromString(fds_bytes)
        pool = descriptor_pool.DescriptorPool()
        for f in fds.file:
            pool.Add(f)
        _class_cache[key] = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
    return _class_cache[key]


def _stamp(ts) -> int:
    return ts.seconds * _NS + ts.nanos


# The end of a PoseInFrame whose seven doubles are all present: pose (field 3) { position (1) { x y z },
# orientation (2) { x y z w } }; None marks the 8 bytes of a double.
_POSE_TAIL = (b"\x1a\x43", b"\x0a\x1b", b"\x09", None, b"\x11", None, b"\x19", None,
              b"\x12\x24", b"\x09", None, b"\x11", None, b"\x19", None, b"\x21", None)
_POSE_TAIL_BYTES = sum(8 if part is None else len(part) for part in _POSE_TAIL)


@dataclass(slots=True)
class _PoseLayout:
    """One byte layout of a whole PoseInFrame message: everything but the seven doubles and the
    timestamp's varint payload bits is fixed (frame id, tags, lengths, varint continuation bits)."""

    frame_id: str
    mask: np.ndarray  # uint8: 0x00 over the doubles, 0x80 over timestamp varints, 0xFF elsewhere
    skel: np.ndarray  # message & mask
    value_idx: np.ndarray  # byte indices of position x y z then orientation x y z w
    sec: tuple[int, int]
    nsec: tuple[int, int]

    @classmethod
    def learn(cls, data: bytes, sample: PoseSample) -> _PoseLayout | None:
        """The layout of `data` if it has the plain one (leading timestamp, frame id, all seven doubles)
        and reading it through the layout gives `sample` (what the full parse decoded) exactly."""
        tail = len(data) - _POSE_TAIL_BYTES
        if tail < 0:
            return None
        doubles = []
        p = tail
        for part in _POSE_TAIL:
            if part is None:
                doubles.append(p)
                p += 8
            elif data[p:p + len(part)] != part:
                return None
            else:
                p += len(part)
        spans = _timestamp_spans(data)
        if spans is None:
            return None
        mask = np.full(len(data), 0xFF, np.uint8)
        for p in doubles:
            mask[p:p + 8] = 0
        for start, n in spans:
            mask[start:start + n] = 0x80
        a = np.frombuffer(data, _U8)
        layout = cls(sample.frame_id, mask, a & mask, np.flatnonzero(mask == 0), *spans)
        values = a[layout.value_idx].view(_F64)
        same = (values.tobytes() == sample.position.tobytes() + sample.orientation.tobytes()
                and layout.stamps(a[None, :]) == [sample.stamp_ns])
        return layout if same else None

    def stamps(self, rows: np.ndarray) -> list[int]:
        return _stamps(rows, self.sec, self.nsec)


class PoseInFrameDecoder:
    """Decodes foxglove.PoseInFrame into PoseSample (`decode`: the full parse); `batch()` reads the
    messages of a known layout (see _PoseLayout) as rows of one array, with the same result."""

    _MAX_LAYOUTS = 8
    # Learning is tried a bounded number of times: a stream whose messages never have the plain layout
    # (a double exactly 0.0 is left out by the encoder, so the fixed tail never matches) would otherwise
    # try it again on every message, on top of the full parse.
    _TRIES_PER_LENGTH = 2  # failed learns of one message length before that length is no longer tried
    _MAX_FAILED_LEARNS = 16  # failed learns in all

    def __init__(self, decode: Decoder) -> None:
        self._decode = decode
        self._layouts: dict[int, _PoseLayout] = {}
        self._failed: dict[int, int] = {}  # message length -> failed learns
        self._failures = 0

    def __call__(self, data: bytes) -> PoseSample:
        sample = self._decode(data)
        n = len(data)
        if self._may_learn(n):
            layout = _PoseLayout.learn(data, sample)
            if layout is None:
                self._failed[n] = self._failed.get(n, 0) + 1
                self._failures += 1
            else:
                self._layouts[n] = layout
        return sample

    def _may_learn(self, n: int) -> bool:
        return (n not in self._layouts and len(self._layouts) < self._MAX_LAYOUTS
                and self._failures < self._MAX_FAILED_LEARNS and self._failed.get(n, 0) < self._TRIES_PER_LENGTH)

    def batch(self, datas: list[bytes]) -> list[PoseSample]:
        out: list = [None] * len(datas)
        for idxs, layout, rows in _by_length(datas, self._layouts.get):
            if layout is None:
                decode = self if self._may_learn(len(datas[idxs[0]])) else self._decode
                for i in idxs:
                    out[i] = decode(datas[i])
                continue
            values = np.ascontiguousarray(rows[:, layout.value_idx]).view(_F64)
            position, orientation = values[:, :3].copy(), values[:, 3:].copy()
            frame_id = layout.frame_id
            decoded = [PoseSample(t, frame_id, p, q)
                       for t, p, q in zip(layout.stamps(rows), position, orientation)]
            for r in _unmatched(rows, layout):
                decoded[r] = self(datas[idxs[r]])
            for i, sample in zip(idxs, decoded):
                out[i] = sample
        return out


def _image_decoder(cls) -> Decoder:
    def decode(data: bytes) -> ImageSample:
        m = cls.FromString(data)
        return ImageSample(_stamp(m.timestamp), m.frame_id, m.data, m.format)

    return decode


def _depth_scale(metadata: dict[str, str] | None) -> float | None:
    if not metadata or DEPTH_SCALE_KEY not in metadata:
        return None
    try:
        scale = float(metadata[DEPTH_SCALE_KEY])
    except ValueError:
        scale = 0.0
    if not (scale > 0 and np.isfinite(scale)):
        raise ValueError(f"channel metadata {DEPTH_SCALE_KEY}={metadata[DEPTH_SCALE_KEY]!r} is not a positive number")
    return scale


def _raw_depth_decoder(cls, scale: float) -> Decoder:
    def decode(data: bytes) -> DepthSample:
        m = cls.FromString(data)
        if m.encoding != "16UC1":
            raise ValueError(f"RawImage encoding {m.encoding!r} is not depth (16UC1)")
        if m.step < 2 * m.width or len(m.data) < m.step * m.height:
            raise ValueError(f"RawImage {m.width}x{m.height} step {m.step}: {len(m.data)} bytes of data is too short")
        rows = np.frombuffer(m.data, "<u2", count=m.step * m.height // 2).reshape(m.height, m.step // 2)
        depth = np.ascontiguousarray(rows[:, :m.width], dtype=np.uint16)
        return DepthSample(_stamp(m.timestamp), m.frame_id, depth, scale, "raw")

    return decode


def _png_depth_decoder(cls, scale: float) -> Decoder:
    def decode(data: bytes) -> DepthSample:
        import cv2

        m = cls.FromString(data)
        depth = cv2.imdecode(np.frombuffer(m.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16 or depth.ndim != 2:
            raise ValueError(f"depth image ({m.format}) is not a 16-bit single-channel PNG")
        return DepthSample(_stamp(m.timestamp), m.frame_id, depth, scale, "png")

    return decode


def _calibration_decoder(cls) -> Decoder:
    def decode(data: bytes) -> CameraInfo:
        m = cls.FromString(data)
        return CameraInfo(_stamp(m.timestamp), m.frame_id, m.width, m.height, tuple(m.K), tuple(m.D),
                          m.distortion_model)

    return decode


def _transforms_decoder(cls) -> Decoder:
    def decode(data: bytes) -> TransformsSample:
        m = cls.FromString(data)
        out = []
        stamp = 0
        for i, t in enumerate(m.transforms):
            if i == 0:
                stamp = _stamp(t.timestamp)
            tr, r = t.translation, t.rotation
            out.append(Transform(t.parent_frame_id, t.child_frame_id, np.array((tr.x, tr.y, tr.z)),
                                 np.array((r.x, r.y, r.z, r.w))))
        return TransformsSample(stamp, tuple(out))

    return decode


# --- foxglove.JointStates: per-layout fast path -----------------------------------------------


_F64 = np.dtype("<f8")
_U8 = np.dtype(np.uint8)


@dataclass(slots=True)
class _Layout:
    """One byte layout of a whole JointStates message: everything but the doubles and the timestamp's
    varint payload bits is fixed (names, tags, lengths, varint continuation bits)."""

    names: tuple[str, ...]
    mask: np.ndarray  # uint8: 0x00 over the doubles, 0x80 over timestamp varints, 0xFF elsewhere
    skeleton: bytes  # message & mask
    skel: np.ndarray  # the same as an array, for checking many messages at once
    pos_idx: np.ndarray  # byte indices of the position doubles, joint-major
    vel_idx: np.ndarray | None
    sec: tuple[int, int]  # (first byte, length) of the seconds varint; length 0 when absent
    nsec: tuple[int, int]

    def stamp(self, data: bytes) -> int:
        return _varint_span(data, *self.sec) * _NS + _varint_span(data, *self.nsec)

    def stamps(self, rows: np.ndarray) -> list[int]:
        return _stamps(rows, self.sec, self.nsec)


def _stamps(rows: np.ndarray, sec_span: tuple[int, int], nsec_span: tuple[int, int]) -> list[int]:
    """The timestamps (ns) of messages given as rows of bytes, from the spans of their varints."""
    key = (sec_span, nsec_span)
    weights = _stamp_weights.get(key)
    if weights is None:
        weights = _stamp_weights[key] = _varint_weights(sec_span, nsec_span)
    idx, w = weights
    both = (rows[:, idx] & 0x7F).astype(np.int64) @ w  # (n, 2): seconds, nanoseconds
    sec, nsec = both[:, 0], both[:, 1]
    if sec.max() < 9_000_000_000:  # no int64 overflow in ns (until the year 2255)
        return (sec * _NS + nsec).tolist()
    return [s * _NS + n for s, n in zip(sec.tolist(), nsec.tolist())]


_stamp_weights: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def _varint_weights(sec_span: tuple[int, int], nsec_span: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The byte indices of both varints (at most 5 bytes each), and each byte's weight (2^(7j)) in the
    seconds column or the nanoseconds one: the 7-bit groups' sum as one product."""
    idx, w = [], []
    for column, (start, n) in enumerate((sec_span, nsec_span)):
        for j in range(n):
            idx.append(start + j)
            w.append([1 << (7 * j), 0] if column == 0 else [0, 1 << (7 * j)])
    return np.array(idx, dtype=np.intp), np.array(w, dtype=np.int64).reshape(len(idx), 2)


def _varint_span(data: bytes, start: int, n: int) -> int:
    r = 0
    for j in range(n):
        r |= (data[start + j] & 0x7F) << (7 * j)
    return r


class JointStatesDecoder:
    """Decodes foxglove.JointStates into JointSample (float64 values bit-exact, names a shared tuple).

    `batch()` decodes many messages of one channel at once: messages of a known layout are checked and
    gathered as rows of one array."""

    _MAX_LAYOUTS = 32

    def __init__(self) -> None:
        self._layouts: dict[int, list[_Layout]] = {}
        self._count = 0

    def __call__(self, data: bytes) -> JointSample:
        for layout in self._layouts.get(len(data), ()):
            a = np.frombuffer(data, _U8)
            if (a & layout.mask).tobytes() == layout.skeleton:
                vel = None if layout.vel_idx is None else a[layout.vel_idx].view(_F64)
                return JointSample(layout.stamp(data), layout.names, a[layout.pos_idx].view(_F64), vel)
        return self._slow(data)

    def batch(self, datas: list[bytes]) -> list[JointSample]:
        out: list = [None] * len(datas)
        for idxs, layout, rows in self._by_layout(datas):
            if layout is None:
                for i in idxs:
                    out[i] = self(datas[i])
                continue
            pos = list(np.ascontiguousarray(rows[:, layout.pos_idx]).view(_F64))
            vel = (repeat(None) if layout.vel_idx is None
                   else list(np.ascontiguousarray(rows[:, layout.vel_idx]).view(_F64)))
            names = layout.names
            decoded = [JointSample(t, names, p, v) for t, p, v in zip(layout.stamps(rows), pos, vel)]
            for r in _unmatched(rows, layout):
                decoded[r] = self(datas[idxs[r]])
            for i, sample in zip(idxs, decoded):
                out[i] = sample
        return out

    def columns(self, datas: list[bytes]) -> tuple[list[int], list[np.ndarray]]:
        """The stamps and positions of many messages of one channel: what batch() would give, without
        making the JointSamples."""
        stamps: list = [None] * len(datas)
        positions: list = [None] * len(datas)
        for idxs, layout, rows in self._by_layout(datas):
            if layout is None:
                for i in idxs:
                    sample = self(datas[i])
                    stamps[i], positions[i] = sample.stamp_ns, sample.positions
                continue
            group_stamps = layout.stamps(rows)
            group_positions = list(np.ascontiguousarray(rows[:, layout.pos_idx]).view(_F64))
            for r in _unmatched(rows, layout):
                sample = self(datas[idxs[r]])
                group_stamps[r], group_positions[r] = sample.stamp_ns, sample.positions
            for i, t, p in zip(idxs, group_stamps, group_positions):
                stamps[i], positions[i] = t, p
        return stamps, positions

    def _by_layout(self, datas: list[bytes]):
        return _by_length(datas, self._first_layout)

    def _first_layout(self, n: int) -> _Layout | None:
        layouts = self._layouts.get(n)
        return layouts[0] if layouts else None

    def _slow(self, data: bytes) -> JointSample:
        stamp, names, pos, vel, pos_off, vel_off, plain = _parse_joint_states(data)
        names = tuple(names)
        if plain and self._count < self._MAX_LAYOUTS:
            self._learn(data, names, pos_off, vel_off)
        velocities = None if vel is None else np.array(vel, dtype=np.float64)
        return JointSample(stamp, names, np.array(pos, dtype=np.float64), velocities)

    def _learn(self, data: bytes, names: tuple[str, ...], pos_off: list[int], vel_off: list[int] | None) -> None:
        spans = _timestamp_spans(data)
        if spans is None:
            return
        sec, nsec = spans
        a = np.frombuffer(data, _U8)
        eight = np.arange(8)
        pos_idx = (np.asarray(pos_off, dtype=np.intp)[:, None] + eight).reshape(-1)
        vel_idx = None if vel_off is None else (np.asarray(vel_off, dtype=np.intp)[:, None] + eight).reshape(-1)
        mask = np.full(a.shape[0], 0xFF, np.uint8)
        mask[pos_idx] = 0
        if vel_idx is not None:
            mask[vel_idx] = 0
        for start, n in (sec, nsec):
            mask[start:start + n] = 0x80
        skel = a & mask
        self._layouts.setdefault(a.shape[0], []).append(
            _Layout(names, mask, skel.tobytes(), skel, pos_idx, vel_idx, sec, nsec))
        self._count += 1


def _by_length(datas: list[bytes], layout_of: Callable):
    """Groups of messages of one length: (their indices, the layout of that length, their bytes as rows
    of an array) where a layout is known and the group is worth an array; (indices, None, None) for
    messages to decode one by one. A group of a length without a layout yet gives its first message
    alone first: decoding it may learn the layout for the rest."""
    by_len: dict[int, list[int]] = {}
    for i, n in enumerate(map(len, datas)):
        idxs = by_len.get(n)
        if idxs is None:
            by_len[n] = [i]
        else:
            idxs.append(i)
    for n, idxs in by_len.items():
        layout = layout_of(n)
        if layout is None and len(idxs) > 4:
            yield idxs[:1], None, None
            idxs = idxs[1:]
            layout = layout_of(n)
        if layout is None or len(idxs) < 4:
            yield idxs, None, None
            continue
        yield idxs, layout, np.frombuffer(b"".join([datas[i] for i in idxs]), _U8).reshape(len(idxs), n)


def _unmatched(rows: np.ndarray, layout) -> list[int]:
    """The rows that do not have the layout (they are decoded one by one)."""
    ok = ((rows & layout.mask) == layout.skel).all(axis=1)
    return [] if ok.all() else np.flatnonzero(~ok).tolist()
