"""Foreign recordings with exactly known content, written with other people's writers (rosbags for ROS 2
MCAP and rosbag2 sqlite3, the `mcap` library with the Foxglove SDK's protobuf schemas), never with
teleprev's: for tests, the interop benchmark and trying `teleprev import` without a robot.

The arm follows teleprev.export.synthetic.arm_q (joints "joint1".."joint6", radians), a gripper
"gripper" (metres) is published by a second publisher on the same JointState topic, the camera frames
carry their frame number (synthetic.read_frame_code), the end effector's pose goes on a PoseStamped
topic and on /tf (base_link -> tool0), and "start" / "stop" strings mark the episodes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.export.synthetic import SyntheticSession, arm_q, render_frame

ARM = tuple(f"joint{i}" for i in range(1, 7))
T0_NS = 1_700_000_000 * 1_000_000_000  # a wall-clock epoch, as ROS stamps are
_NS = 1_000_000_000


def gripper_q(t_s):
    return 0.04 + 0.03 * np.sin(2 * np.pi * 0.3 * np.asarray(t_s, dtype=float))


@dataclass(frozen=True)
class ForeignSpec:
    episodes: tuple[tuple[float, float], ...] = ((0.0, 3.0),)  # (start, stop) seconds of each demonstration
    joint_hz: float = 100.0
    camera_hz: float = 30.0
    pose_hz: float = 50.0
    width: int = 160
    height: int = 120
    raw_images: bool = False  # sensor_msgs/Image (bgr8) instead of CompressedImage (JPEG)
    events: bool = True  # "start" / "stop" on /episode_events
    latency_ms: float = 2.0  # log time = stamp + latency
    header_offset_s: float = 0.0  # header stamps this far from the log clock (a device or simulation clock)

    def times(self, hz: float) -> np.ndarray:
        """Sample times (s) of a stream: only while a demonstration runs (silence between them)."""
        return np.concatenate([np.arange(a, b, 1.0 / hz) for a, b in self.episodes])


def _frame(spec: ForeignSpec, k: int, t: float) -> np.ndarray:
    return render_frame(SyntheticSession((), width=spec.width, height=spec.height), k, t, 0, None)  # BGR


def _events(spec: ForeignSpec):
    """(stamp_ns, kind, value) in time order; kind: joints, gripper, image, pose, event."""
    out = []
    for t in spec.times(spec.joint_hz):
        out.append((t, "joints", arm_q(t)))
        out.append((t + 0.0005, "gripper", gripper_q(t)))
    for k, t in enumerate(spec.times(spec.camera_hz)):
        out.append((t, "image", k))
    for t in spec.times(spec.pose_hz):
        out.append((t, "pose", None))
    if spec.events:
        for a, b in spec.episodes:
            out += [(a - 0.01, "event", "start"), (b, "event", "stop")]
    out.sort(key=lambda e: e[0])
    return [(T0_NS + int(round(t * _NS)), kind, value, t) for t, kind, value in out]


def write_ros2(path: str | Path, spec: ForeignSpec = ForeignSpec(), storage: str = "mcap", zstd: bool = False) -> Path:
    """A rosbag2 recording (a folder) written by rosbags; storage "mcap" or "sqlite3", each message
    zstd-compressed with `zstd`. Returns the folder."""
    import cv2
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    image_type = "sensor_msgs/msg/Image" if spec.raw_images else "sensor_msgs/msg/CompressedImage"
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    lat = int(spec.latency_ms * 1e6)

    def header(ns: int, frame: str = ""):
        ns += int(spec.header_offset_s * _NS)
        return Header(stamp=Time(sec=ns // _NS, nanosec=ns % _NS), frame_id=frame)

    def pose_parts(t: float):
        q = arm_q(t)
        position = np.array([0.3 + 0.1 * q[0], 0.1 * q[1], 0.4 + 0.1 * q[2]])
        return position, np.array([0.0, 0.0, np.sin(q[3] / 2), np.cos(q[3] / 2)])

    path = Path(path)
    writer = Writer(path, version=9, storage_plugin=plugin)
    if zstd:
        writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with writer as w:
        c = {
            "joints": w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts),
            "image": w.add_connection("/camera/front/image", image_type, typestore=ts),
            "pose": w.add_connection("/ee_pose", "geometry_msgs/msg/PoseStamped", typestore=ts),
            "tf": w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts),
            "event": w.add_connection("/episode_events", "std_msgs/msg/String", typestore=ts),
        }
        for ns, kind, value, t in _events(spec):
            if kind in ("joints", "gripper"):
                names = list(ARM) if kind == "joints" else ["gripper"]
                msg = T["sensor_msgs/msg/JointState"](header=header(ns), name=names,
                                                      position=np.asarray(value, dtype=np.float64).reshape(-1),
                                                      velocity=np.zeros(0), effort=np.zeros(0))
                w.write(c["joints"], ns + lat, ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
            elif kind == "image":
                bgr = _frame(spec, value, t)
                if spec.raw_images:
                    h, wd = bgr.shape[:2]
                    msg = T[image_type](header=header(ns, "camera"), height=h, width=wd, encoding="bgr8",
                                        is_bigendian=0, step=wd * 3, data=bgr.reshape(-1))
                else:
                    ok, jpg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90])
                    msg = T[image_type](header=header(ns, "camera"), format="jpeg", data=jpg.reshape(-1))
                w.write(c["image"], ns + lat, ts.serialize_cdr(msg, image_type))
            elif kind == "pose":
                p, q = pose_parts(t)
                P, Q = (
                    T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                    T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
                )
                pose = T["geometry_msgs/msg/PoseStamped"](header=header(ns, "base_link"),
                                                          pose=T["geometry_msgs/msg/Pose"](position=P, orientation=Q))
                w.write(c["pose"], ns + lat, ts.serialize_cdr(pose, "geometry_msgs/msg/PoseStamped"))
                tr = T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]), rotation=Q
                )
                tf = T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
                    header=header(ns, "base_link"), child_frame_id="tool0", transform=tr)])
                w.write(c["tf"], ns + lat, ts.serialize_cdr(tf, "tf2_msgs/msg/TFMessage"))
            else:
                msg = T["std_msgs/msg/String"](data=value)
                w.write(c["event"], ns + lat, ts.serialize_cdr(msg, "std_msgs/msg/String"))
    return path


def write_foxglove_mcap(path: str | Path, spec: ForeignSpec = ForeignSpec()) -> Path:
    """An MCAP of foxglove.JointStates / CompressedImage / PoseInFrame (protobuf), written with the
    `mcap` library and the Foxglove SDK's schemas and encoders, without teleprev's episode events: the
    arm and gripper together on /joints."""
    import cv2
    import foxglove.messages as fm
    from mcap.writer import CompressionType, Writer

    path = Path(path)
    with open(path, "xb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="interop-sample")
        channels = {}
        for topic, cls in (
            ("/joints", fm.JointStates),
            ("/camera/front", fm.CompressedImage),
            ("/ee_pose", fm.PoseInFrame),
        ):
            schema = cls.get_schema()
            sid = w.register_schema(schema.name, schema.encoding, bytes(schema.data))
            channels[topic] = w.register_channel(topic, "protobuf", sid)
        lat = int(spec.latency_ms * 1e6)
        for ns, kind, value, t in _events(spec):
            stamp = fm.Timestamp(sec=ns // _NS, nsec=ns % _NS)
            if kind == "joints":
                q = np.r_[value, gripper_q(t)]
                data = fm.JointStates(timestamp=stamp, joints=[fm.JointState(name=n, position=float(v))
                                                               for n, v in zip(ARM + ("gripper",), q)]).encode()
                w.add_message(channels["/joints"], ns + lat, data, ns + lat)
            elif kind == "image":
                ok, jpg = cv2.imencode(".jpg", _frame(spec, value, t), [cv2.IMWRITE_JPEG_QUALITY, 90])
                data = fm.CompressedImage(
                    timestamp=stamp, frame_id="camera", data=jpg.tobytes(), format="jpeg"
                ).encode()
                w.add_message(channels["/camera/front"], ns + lat, data, ns + lat)
            elif kind == "pose":
                q = arm_q(t)
                pose = fm.Pose(
                    position=fm.Vector3(x=0.3 + 0.1 * q[0], y=0.1 * q[1], z=0.4 + 0.1 * q[2]),
                    orientation=fm.Quaternion(x=0.0, y=0.0, z=float(np.sin(q[3] / 2)), w=float(np.cos(q[3] / 2))),
                )
                data = fm.PoseInFrame(timestamp=stamp, frame_id="base_link", pose=pose).encode()
                w.add_message(channels["/ee_pose"], ns + lat, data, ns + lat)
        w.finish()
    return path


def ros2_mcap_file(folder: Path) -> Path:
    """The .mcap file inside a rosbag2 folder written with storage "mcap" (a bare ROS 2 MCAP)."""
    return next(Path(folder).glob("*.mcap"))
