"""One episode's streams read from a session: joint and pose streams into arrays, camera streams as
frame stamps only (their images are read again, one at a time, while the episode is written).

Memory is bounded by one episode's joint samples (a few MB for ten minutes), never by its images.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.errors import SessionError
from teleprev.export.recipe import IMAGE, POSE, POSE_NAMES
from teleprev.messages import DepthSample, ImageSample, JointSample, PoseSample


@dataclass
class JointStream:
    topic: str
    names: tuple[str, ...]  # column order of `values`
    stamps: np.ndarray  # int64, ascending
    values: np.ndarray  # float64 (n, len(names))
    velocities: np.ndarray | None = None  # float64 (n, len(names)), where every sample carries them


@dataclass
class CameraStream:
    topic: str
    stamps: np.ndarray  # int64, ascending
    ordinal: np.ndarray  # for each stamp, the message's position among the topic's messages in the window


class _Growing:
    """Stamps and value rows appended one at a time into arrays that double when full."""

    def __init__(self, width: int):
        self.n = 0
        self.stamps = np.empty(1024, dtype=np.int64)
        self.values = np.empty((1024, width), dtype=np.float64)
        self.velocities = np.empty((1024, width), dtype=np.float64)
        self.every_velocity = True  # every sample so far carried velocities

    def add(self, stamp: int, row, velocity=None) -> None:
        if self.n == len(self.stamps):
            self.stamps = np.resize(self.stamps, 2 * self.n)
            self.values = np.resize(self.values, (2 * self.n, self.values.shape[1]))
            self.velocities = np.resize(self.velocities, (2 * self.n, self.values.shape[1]))
        self.stamps[self.n] = stamp
        self.values[self.n] = row
        if velocity is None or len(velocity) != self.values.shape[1]:
            self.every_velocity = False
        else:
            self.velocities[self.n] = velocity
        self.n += 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        stamps, values = self.stamps[: self.n], self.values[: self.n]
        velocities = self.velocities[: self.n] if self.every_velocity and self.n else None
        if self.n > 1 and np.any(np.diff(stamps) < 0):
            order = np.argsort(stamps, kind="stable")
            stamps, values = stamps[order], values[order]
            velocities = None if velocities is None else velocities[order]
        return stamps, values, velocities


def pose_values(p: PoseSample) -> np.ndarray:
    """A pose as a dataset's vector holds it: position, then orientation (POSE_NAMES)."""
    return np.concatenate([p.position, p.orientation])


def probe_joint_names(reader, topic: str, schema: str) -> tuple[str, ...]:
    """The joint names of a stream, from its first message (a pose: x y z qx qy qz qw)."""
    if schema == POSE:
        return POSE_NAMES
    for msg in reader.messages([topic]):
        if not isinstance(msg.payload, JointSample):
            raise SessionError(
                f"{topic} holds {type(msg.payload).__name__} messages, expected joint states", str(reader.path)
            )
        return tuple(msg.payload.names)
    raise SessionError(f"{topic} has no messages", str(reader.path))


def read_episode(reader, joint_topics: dict[str, tuple[str, ...]], camera_topics: list[str], lo_ns: int, hi_ns: int
                 ) -> tuple[dict[str, JointStream], dict[str, CameraStream]]:
    """Messages logged in [lo_ns, hi_ns) of the given topics. `joint_topics` maps a topic to the joint
    names its columns must follow (a sample with other names is reordered by name, or refused)."""
    where = str(reader.path)
    joints = {t: _Growing(len(names)) for t, names in joint_topics.items()}
    cams: dict[str, list[int]] = {t: [] for t in camera_topics}
    index = {t: {n: i for i, n in enumerate(names)} for t, names in joint_topics.items()}
    topics = list(joint_topics) + list(camera_topics)
    if not topics:
        return {}, {}
    for msg in reader.messages(topics, lo_ns, hi_ns):
        p = msg.payload
        t = msg.topic
        if t in cams:
            if not isinstance(p, (ImageSample, DepthSample)):
                raise SessionError(
                    f"{t} at log time {msg.log_time_ns}: expected an image, got {type(p).__name__}", where
                )
            cams[t].append(p.stamp_ns)
        elif type(p) is JointSample:
            names = joint_topics[t]
            if p.names == names:
                joints[t].add(p.stamp_ns, p.positions, p.velocities)
            else:
                joints[t].add(p.stamp_ns, _reorder(p, names, index[t], t, msg.log_time_ns, where))
        elif type(p) is PoseSample:
            joints[t].add(p.stamp_ns, pose_values(p))
        else:
            raise SessionError(f"{t} at log time {msg.log_time_ns}: unexpected {type(p).__name__} message", where)
    out_j = {}
    for t, g in joints.items():
        stamps, values, velocities = g.arrays()
        out_j[t] = JointStream(t, joint_topics[t], stamps, values, velocities)
    out_c = {}
    for t, stamps in cams.items():
        s = np.asarray(stamps, dtype=np.int64)
        order = np.argsort(s, kind="stable")
        out_c[t] = CameraStream(t, s[order], order)
    return out_j, out_c


def _reorder(
    p: JointSample, names: tuple[str, ...], index: dict[str, int], topic: str, log_ns: int, where: str
) -> np.ndarray:
    if len(p.names) != len(names) or set(p.names) != set(names):
        raise SessionError(f"{topic} at log time {log_ns}: joints {list(p.names)} differ from the stream's "
                           f"first message {list(names)}", where)
    row = np.empty(len(names))
    row[[index[n] for n in p.names]] = p.positions
    return row


def is_image(schema: str) -> bool:
    return schema == IMAGE
