"""ROS 2 depth images into a LeRobot depth feature: sensor_msgs/Image 16UC1 and a compressedDepth PNG
(compressed_depth_image_transport's 12-byte header, then the PNG), in a rosbag2 written by rosbags, read
back through LeRobotDataset in metres."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

from teleprev.errors import SessionError
from teleprev.export.foreign.config import load_import_recipe
from teleprev.export.foreign.ros import RosBagReader
from teleprev.export.foreign.run import import_files
from teleprev.messages import DepthSample

W, H, NS = 64, 48, 1_000_000_000
T0 = 1_700_000_000 * NS
RAW, PACKED = "/camera/wrist/depth/image_raw", "/camera/wrist/depth/image_raw/compressedDepth"
DEPTH_MIN = 0.01  # lerobot's default depth_min


def half_step_m(depth_m):
    """Half of lerobot's log quantisation step (12 bits over 0.01..10 m, shift 3.5 m) at depth_m."""
    return (depth_m + 3.5) * (np.log(13.5) - np.log(3.51)) / 4095 / 2


def depth_mm(i: int) -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W]
    d = (400 + 5 * yy + 3 * xx + 7 * i).astype(np.uint16)  # 0.4..0.9 m
    d[5, 5] = 0  # no return
    return d


def write_bag(path: Path, seconds: float = 1.5, bad_format: bool = False) -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types

    def header(ns: int):
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=ns // NS, nanosec=ns % NS),
                                        frame_id="wrist_depth")

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        joints = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        raw = w.add_connection(RAW, "sensor_msgs/msg/Image", typestore=ts)
        packed = w.add_connection(PACKED, "sensor_msgs/msg/CompressedImage", typestore=ts)
        for k in range(int(seconds * 100)):
            ns = T0 + k * 10_000_000
            msg = T["sensor_msgs/msg/JointState"](header=header(ns), name=["joint1"], position=np.array([k / 100]),
                                                  velocity=np.zeros(0), effort=np.zeros(0))
            w.write(joints, ns, ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
            if k % 3 == 0:
                i = k // 3
                d = depth_mm(i)
                img = T["sensor_msgs/msg/Image"](header=header(ns), height=H, width=W, encoding="16UC1",
                                                 is_bigendian=0, step=2 * W, data=d.view(np.uint8).reshape(-1))
                w.write(raw, ns, ts.serialize_cdr(img, "sensor_msgs/msg/Image"))
                ok, png = cv2.imencode(".png", d)
                config = struct.pack("<iff", 1, 0.0, 0.0)  # PNG; depthParam is for 32FC1 only
                fmt = "16UC1; jpeg" if bad_format and i == 5 else "16UC1; compressedDepth png"
                data = np.frombuffer(config + png.tobytes(), np.uint8)
                c = T["sensor_msgs/msg/CompressedImage"](header=header(ns), format=fmt, data=data)
                w.write(packed, ns, ts.serialize_cdr(c, "sensor_msgs/msg/CompressedImage"))
    return path


def recipe(tmp_path: Path, topic: str) -> Path:
    path = tmp_path / "r.toml"
    path.write_text(f"""[import]
episodes = "file"
[export]
fps = 30
min_episode_s = 0.5
[[feature]]
name = "observation.state"
streams = ["/joint_states"]
[[feature]]
name = "action"
streams = ["/joint_states"]
timing = "next"
[[feature]]
name = "observation.images.wrist_depth"
streams = ["{topic}"]
""")
    return path


def test_both_ros_depth_forms_read_as_depth_in_millimetres(tmp_path):
    bag = write_bag(tmp_path / "bag")
    reader = RosBagReader(bag, load_import_recipe(recipe(tmp_path, RAW)))
    try:
        assert reader.topics[RAW].schema == reader.topics[PACKED].schema == "foxglove.RawImage"
        for topic in (RAW, PACKED):
            got = [m.payload for m in reader.messages([topic])]
            assert len(got) == 50 and all(isinstance(d, DepthSample) and d.scale_m == 0.001 for d in got)
            assert all(np.array_equal(d.depth, depth_mm(i)) for i, d in enumerate(got))
            assert got[0].frame_id == "wrist_depth"
    finally:
        reader.close()


@pytest.mark.parametrize("topic", [RAW, PACKED])
def test_ros_depth_imports_into_a_lerobot_depth_feature(tmp_path, topic):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    bag = write_bag(tmp_path / "bag")
    import_files([bag], load_import_recipe(recipe(tmp_path, topic)), "t/depth", tmp_path / "out")
    ds = LeRobotDataset("t/depth", root=tmp_path / "out", video_backend="pyav", depth_output_unit="m")
    assert ds.meta.features["observation.images.wrist_depth"]["info"]["is_depth_map"] is True
    assert len(ds) >= 40
    for k in (0, 17, len(ds) - 1):
        got = ds[k]["observation.images.wrist_depth"].numpy().reshape(H, W)
        # the frame it is: the recorded one it matches best (they differ by 7 mm each)
        errors = [np.abs(got - depth_mm(i) / 1000)[depth_mm(i) > 0].max() for i in range(50)]
        want = depth_mm(int(np.argmin(errors))) / 1000
        seen = want > 0
        assert np.all(np.abs(got - want)[seen] <= half_step_m(want[seen]) + 1e-6)
        assert got[5, 5] == pytest.approx(DEPTH_MIN, abs=1e-4)


def test_a_compressed_depth_message_that_is_not_one_is_named(tmp_path):
    bag = write_bag(tmp_path / "bag", bad_format=True)
    reader = RosBagReader(bag, load_import_recipe(recipe(tmp_path, PACKED)))
    try:
        with pytest.raises(SessionError, match="format '16UC1; jpeg' is not a 16UC1 compressedDepth PNG"):
            list(reader.messages([PACKED]))
    finally:
        reader.close()
