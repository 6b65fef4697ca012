"""ROS 2 recordings: a ROS 2 MCAP file, a rosbag2 folder (sqlite3 or MCAP storage) or a bare .db3,
read with `rosbags` (pure Python: CDR decoding from the message definitions stored in the file, and
both rosbag2 storages, without a ROS installation).

Messages become teleprev payloads:
    sensor_msgs/msg/JointState       JointSample   positions (rad, m); streams that several publishers
                                                   share (/joint_states) are merged: each message updates
                                                   its joints and a sample is given once all are known
    sensor_msgs/msg/CompressedImage  ImageSample   the JPEG/PNG bytes as recorded
    sensor_msgs/msg/Image            ImageSample   data an RGB array (rgb8, bgr8, rgba8, bgra8, mono8)
                                     DepthSample   16UC1 / mono16: depth in millimetres (REP 118)
    sensor_msgs/msg/CompressedImage  DepthSample   "16UC1; compressedDepth" (image_transport's
                                                   compressed_depth_image_transport: a 12-byte header, then
                                                   a 16-bit PNG), millimetres
    geometry_msgs/msg/PoseStamped    PoseSample
    tf2_msgs/msg/TFMessage           TransformsSample; each child frame also reads as a pose topic
                                                   "<tf topic>/<child>" (the child in its parent)
    std_msgs/msg/String              Event {"data": text} (episode events)
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from teleprev.errors import SessionError
from teleprev.export.foreign.config import ImportRecipe
from teleprev.export.foreign.episodes import cut_episodes
from teleprev.export.recipe import IMAGE, JOINTS, POSE
from teleprev.messages import (
    DepthSample,
    Event,
    ImageSample,
    JointSample,
    Logged,
    PoseSample,
    Transform,
    TransformsSample,
)
from teleprev.session.codec import FRAME_TRANSFORMS, RAW_IMAGE
from teleprev.session.reader import Episode, TopicInfo

TEXT = "std_msgs/msg/String"
_SCHEMAS = {
    "sensor_msgs/msg/JointState": JOINTS,
    "sensor_msgs/msg/CompressedImage": IMAGE,
    "sensor_msgs/msg/Image": IMAGE,
    "geometry_msgs/msg/PoseStamped": POSE,
    "tf2_msgs/msg/TFMessage": FRAME_TRANSFORMS,
    TEXT: TEXT,
}
_SCAN = 200  # messages read to learn a joint stream's names or a TF topic's child frames
CLOCK_SKEW_NS = 5_000_000_000  # header stamps further than this from the log times are on another clock
_DEPTH_ENCODINGS = ("16uc1", "mono16")  # sensor_msgs/Image depth: uint16 millimetres (REP 118)
_MM = 0.001
_COMPRESSED_DEPTH_HEADER = 12  # compressed_depth_image_transport's ConfigHeader: format (int32), depthParam[2]
_CHANNELS = {"rgb8": (3, (0, 1, 2)), "bgr8": (3, (2, 1, 0)), "rgba8": (4, (0, 1, 2)), "bgra8": (4, (2, 1, 0)),
             "8uc3": (3, (2, 1, 0)), "mono8": (1, (0, 0, 0)), "8uc1": (1, (0, 0, 0))}


class RosBagReader:
    """A ROS 2 recording with SessionReader's surface (see teleprev/export/foreign/__init__.py)."""

    def __init__(self, path: str | Path, recipe: ImportRecipe):
        from rosbags.highlevel import AnyReader

        self.path = Path(path)
        self.recipe = recipe
        self._use_header = recipe.section.timestamps == "header"
        from rosbags.typesys import Stores, get_typestore

        try:  # the standard types for a bag that stores no definitions (ROS 2 Humble's sqlite3 bags)
            self._bag = AnyReader([self.path], default_typestore=get_typestore(Stores.LATEST))
            self._bag.open()
        except Exception as exc:  # rosbags raises several kinds (its own, OSError, KeyError...) for unreadable files
            raise SessionError(f"not a readable ROS 2 recording ({exc})", str(self.path)) from None
        if not self._bag.message_count:
            topics = ", ".join(sorted({c.topic for c in self._bag.connections})) or "none"
            self.close()
            raise SessionError(f"the recording holds no messages (its topics: {topics})", str(self.path))
        self._conns: dict[str, list] = {}
        for c in self._bag.connections:
            self._conns.setdefault(c.topic, []).append(c)
        self._names: dict[str, tuple[str, ...]] = {}
        self._frames: dict[str, tuple[str, str]] = {}  # virtual pose topic -> (tf topic, child frame)
        self.metadata = {"rig": {"robot": recipe.robot_type}, "session": {"task": recipe.section.task},
                         "import": {"source": str(self.path), "format": "ros2"}}
        self.start_ns = self._bag.start_time if self._bag.message_count else None
        self.end_ns = self._bag.end_time if self._bag.message_count else None
        try:
            self.topics = self._topic_infos()
            if self._use_header:
                self._check_clocks()
        except BaseException:
            self.close()
            raise

    def _topic_infos(self) -> dict[str, TopicInfo]:
        out = {}
        for topic, conns in sorted(self._conns.items()):
            msgtype = conns[0].msgtype
            schema = _SCHEMAS.get(msgtype, msgtype)
            if schema == IMAGE and self._carries_depth(topic, msgtype):
                schema = RAW_IMAGE  # read as DepthSample: the export's depth role takes it
            count = sum(c.msgcount for c in conns)
            out[topic] = TopicInfo(topic, schema, "cdr", count, None, None)
            if schema == FRAME_TRANSFORMS:
                for child in self._children(topic):
                    name = f"{topic.rstrip('/')}/{child}"
                    self._frames[name] = (topic, child)
                    out[name] = TopicInfo(name, POSE, "cdr", count, None, None)
        return out

    def _check_clocks(self) -> None:
        """Frames are planned on the stamps and episodes read by log time: the two must share a clock."""
        for topic, info in self.topics.items():
            if info.schema not in (JOINTS, IMAGE, POSE, RAW_IMAGE) or topic in self._frames:
                continue
            for _, log_ns, msg in self._raw([topic]):
                stamp = self._stamp(msg.header, log_ns)
                if abs(stamp - log_ns) > CLOCK_SKEW_NS:
                    raise SessionError(f"{topic}: header stamps are {(stamp - log_ns) / 1e9:+.1f} s from the times the "
                                       "messages were logged (another clock, e.g. simulation time); set [import] "
                                       'timestamps = "log"', str(self.path))
                break

    def _carries_depth(self, topic: str, msgtype: str) -> bool:
        """Whether an image topic's first message is depth (16UC1, or a compressedDepth PNG)."""
        for _, _, msg in self._raw([topic]):
            if msgtype.endswith("CompressedImage"):
                return "compresseddepth" in msg.format.lower()
            return msg.encoding.lower() in _DEPTH_ENCODINGS
        return False

    def _children(self, topic: str) -> list[str]:
        seen: dict[str, None] = {}
        for k, (_, _, msg) in enumerate(self._raw([topic])):
            for t in msg.transforms:
                seen.setdefault(t.child_frame_id)
            if k >= _SCAN:
                break
        return list(seen)

    # --- messages ---

    def _raw(self, topics: Iterable[str], start_ns: int | None = None, end_ns: int | None = None):
        conns = [c for t in topics for c in self._conns.get(t, [])]
        if not conns:
            return
        for conn, log_ns, raw in self._bag.messages(conns, start=start_ns, stop=end_ns):
            try:
                yield conn, log_ns, self._bag.deserialize(raw, conn.msgtype)
            except Exception as exc:  # a message its own definition does not decode
                raise SessionError(f"message on {conn.topic} at log time {log_ns} does not decode: {exc}",
                                   str(self.path)) from None

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[Logged]:
        """Messages with start_ns <= log time < end_ns, in log time order, as teleprev payloads."""
        if topics is None:
            topics = [t for t, info in self.topics.items() if info.schema in (JOINTS, IMAGE, POSE, RAW_IMAGE)]
        elif isinstance(topics, str):
            topics = [topics]
        wanted = list(topics)
        for t in wanted:
            if t not in self.topics:
                raise SessionError(f"no topic {t!r} in this file (topics: {', '.join(sorted(self.topics))})",
                                   str(self.path))
        poses: dict[str, list[tuple[str, str]]] = {}  # tf topic -> [(virtual topic, child)]
        real = set()
        for t in wanted:
            if t in self._frames:
                tf, child = self._frames[t]
                poses.setdefault(tf, []).append((t, child))
            else:
                real.add(t)
        merged = {t: _JointMerge(self.joint_names(t)) for t in real if self.topics[t].schema == JOINTS}
        for conn, log_ns, msg in self._raw(real | set(poses), start_ns, end_ns):
            topic = conn.topic
            schema = self.topics[topic].schema
            if topic in poses:
                for name, child in poses[topic]:
                    for t in msg.transforms:
                        if t.child_frame_id == child:
                            yield Logged(name, log_ns, _pose_of(t, self._stamp(t.header, log_ns)))
                if topic not in real:
                    continue
            if schema == JOINTS:
                sample = merged[topic].update(msg, self._stamp(msg.header, log_ns))
                if sample is not None:
                    yield Logged(topic, log_ns, sample)
            elif schema == IMAGE:
                yield Logged(topic, log_ns, self._image(conn.msgtype, msg, log_ns))
            elif schema == RAW_IMAGE:
                yield Logged(topic, log_ns, self._depth(conn.msgtype, msg, log_ns))
            elif schema == POSE:
                p, q = msg.pose.position, msg.pose.orientation
                yield Logged(topic, log_ns, PoseSample(self._stamp(msg.header, log_ns), msg.header.frame_id,
                                                       np.array((p.x, p.y, p.z)), np.array((q.x, q.y, q.z, q.w))))
            elif schema == FRAME_TRANSFORMS:
                yield Logged(topic, log_ns, _transforms(msg, self._stamp, log_ns))
            elif schema == TEXT:
                yield Logged(topic, log_ns, Event(log_ns, TEXT, {"data": msg.data}))

    def _stamp(self, header, log_ns: int) -> int:
        if self._use_header:
            ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
            if ns > 0:
                return ns
        return int(log_ns)

    def _image(self, msgtype: str, msg, log_ns: int) -> ImageSample:
        stamp = self._stamp(msg.header, log_ns)
        if msgtype.endswith("CompressedImage"):
            return ImageSample(stamp, msg.header.frame_id, bytes(msg.data), msg.format)
        enc = msg.encoding.lower()
        if enc not in _CHANNELS:
            raise SessionError(f"image at log time {log_ns}: encoding {msg.encoding!r} is not supported "
                               f"(supported: {', '.join(_CHANNELS)})", str(self.path))
        n, order = _CHANNELS[enc]
        h, w, step = int(msg.height), int(msg.width), int(msg.step)
        data = np.asarray(msg.data, dtype=np.uint8)
        if step < w * n or len(data) < h * step:
            raise SessionError(f"image at log time {log_ns}: {len(data)} bytes for {w}x{h} {enc} with step {step}",
                               str(self.path))
        pixels = data[: h * step].reshape(h, step)[:, : w * n].reshape(h, w, n)
        return ImageSample(stamp, msg.header.frame_id, pixels[:, :, list(order)], "raw")

    def _depth(self, msgtype: str, msg, log_ns: int) -> DepthSample:
        stamp, where = self._stamp(msg.header, log_ns), str(self.path)
        if msgtype.endswith("CompressedImage"):
            import cv2

            data = np.asarray(msg.data, dtype=np.uint8)
            if "compresseddepth" not in msg.format.lower() or not msg.format.lower().startswith("16uc1"):
                raise SessionError(f"depth image at log time {log_ns}: format {msg.format!r} is not a 16UC1 "
                                   "compressedDepth PNG", where)
            depth = cv2.imdecode(data[_COMPRESSED_DEPTH_HEADER:], cv2.IMREAD_UNCHANGED)
            if depth is None or depth.dtype != np.uint16 or depth.ndim != 2:
                raise SessionError(f"depth image at log time {log_ns}: the compressedDepth data is not a 16-bit "
                                   "PNG after its 12-byte header", where)
            return DepthSample(stamp, msg.header.frame_id, depth, _MM)
        enc = msg.encoding.lower()
        if enc not in _DEPTH_ENCODINGS:
            raise SessionError(f"depth image at log time {log_ns}: encoding {msg.encoding!r} is not 16UC1 depth "
                               "(the topic's first image was)", where)
        h, w, step = int(msg.height), int(msg.width), int(msg.step)
        data = np.asarray(msg.data, dtype=np.uint8)
        if step < 2 * w or len(data) < h * step:
            raise SessionError(f"depth image at log time {log_ns}: {len(data)} bytes for {w}x{h} {enc} with step "
                               f"{step}", where)
        order = ">u2" if msg.is_bigendian else "<u2"
        rows = data[: h * step].reshape(h, step)[:, : 2 * w]
        depth = np.ascontiguousarray(rows).view(order).reshape(h, w).astype(np.uint16)
        return DepthSample(stamp, msg.header.frame_id, depth, _MM)

    # --- joint names ---

    def joint_names(self, topic: str) -> tuple[str, ...]:
        """The joints a JointState stream is given with: the recipe's list or the URDF's joints (in that
        order), else every joint seen in its first messages, in the order they appear."""
        if topic in self._names:
            return self._names[topic]
        seen: dict[str, None] = {}
        for k, (_, _, msg) in enumerate(self._raw([topic])):
            for n in msg.name:
                seen.setdefault(n)
            if k >= _SCAN:
                break
        if not seen:
            raise SessionError(f"{topic} has no joint states", str(self.path))
        names = self.recipe.select_joints(topic, tuple(seen), str(self.path))
        self._names[topic] = names
        return names

    def episodes(self) -> list[Episode]:
        joints = [t for t, info in self.topics.items() if info.schema == JOINTS]
        return cut_episodes(self, self.recipe.section, joints)

    def close(self) -> None:
        try:
            self._bag.close()
        except Exception:  # already closed
            pass


class _JointMerge:
    """The latest position of every wanted joint; a sample once all are known."""

    def __init__(self, names: tuple[str, ...]):
        self.names = names
        self.index = {n: i for i, n in enumerate(names)}
        self.values = np.full(len(names), np.nan)
        self.known = np.zeros(len(names), dtype=bool)

    def update(self, msg, stamp: int) -> JointSample | None:
        pos = msg.position
        hit = False
        for k, n in enumerate(msg.name):
            i = self.index.get(n)
            if i is not None and k < len(pos):
                self.values[i] = pos[k]
                self.known[i] = True
                hit = True
        if not hit or not self.known.all():
            return None
        return JointSample(stamp, self.names, self.values.copy())


def _pose_of(t, stamp: int) -> PoseSample:
    tr, r = t.transform.translation, t.transform.rotation
    return PoseSample(stamp, t.header.frame_id, np.array((tr.x, tr.y, tr.z)), np.array((r.x, r.y, r.z, r.w)))


def _transforms(msg, stamp_of, log_ns: int) -> TransformsSample:
    out = []
    stamp = log_ns
    for i, t in enumerate(msg.transforms):
        if i == 0:
            stamp = stamp_of(t.header, log_ns)
        tr, r = t.transform.translation, t.transform.rotation
        out.append(Transform(t.header.frame_id, t.child_frame_id, np.array((tr.x, tr.y, tr.z)),
                             np.array((r.x, r.y, r.z, r.w))))
    return TransformsSample(stamp, tuple(out))
