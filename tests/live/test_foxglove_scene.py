"""A session opens in Foxglove as one scene: the rig's URDF attached and on /robot_description (ROS 2
std_msgs/String, what Foxglove's URDF layer reads from a topic), /tf at the arm state's rate, and the
camera and suit frames hung on the robot's tree. Read back with the mcap library and rosbags' CDR
decoder, not with teleprev's reader."""

from __future__ import annotations

import numpy as np
import pytest

from teleprev.errors import ConfigError
from teleprev.rig import default_rig_path, load_rig_text
from teleprev.robot.model import load_robot
from teleprev.transforms import quat_to_matrix


@pytest.fixture
def session(sim_session):
    return sim_session


def _read(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        attachments = list(reader.iter_attachments())
        messages = [(ch.topic, schema, msg) for schema, ch, msg in reader.iter_messages(log_time_order=True)]
    return summary, attachments, messages


def test_the_robot_is_in_the_session(session):
    summary, attachments, messages = _read(session)
    urdf = load_robot("xarm6_leap_hand").urdf_path
    assert [(a.name, a.media_type) for a in attachments] == [("xarm6_leap_hand.urdf", "application/xml")]
    assert attachments[0].data == urdf.read_bytes()
    described = [(s, m) for t, s, m in messages if t == "/robot_description"]
    assert len(described) == 1
    schema, msg = described[0]
    assert (schema.name, schema.encoding) == ("std_msgs/msg/String", "ros2msg")
    from rosbags.typesys import Stores, get_typestore

    text = get_typestore(Stores.ROS2_HUMBLE).deserialize_cdr(msg.data, "std_msgs/msg/String").data
    assert text == urdf.read_text()
    # before any /tf, so the URDF layer has the robot from the first frame on
    first_tf = min(m.log_time for t, s, m in messages if t == "/tf")
    assert msg.log_time < first_tf
    # teleprev's own reader reads it too
    from teleprev.session.reader import SessionReader

    with SessionReader(session) as r:
        assert next(iter(r.messages(["/robot_description"]))).payload.urdf == text


def test_tf_runs_at_the_arm_state_rate_and_connects_every_sensor_frame(session):
    from teleprev.session.reader import SessionReader

    with SessionReader(session) as r:
        arm = [m.payload.stamp_ns for m in r.messages(["/arm/arm/state"])]
        tf = [m.payload for m in r.messages(["/tf"])]
        image_frames = {m.payload.frame_id for m in r.messages(["/camera/cam_front/image"])}
        wrist_frames = {m.payload.frame_id for m in r.messages(["/suit/suit/wrist"])}
    assert len(tf) == len(arm) and [t.stamp_ns for t in tf] == arm  # one /tf per arm state, at its stamp
    parents = {tr.child: tr.parent for tr in tf[-1].transforms}
    robot = load_robot("xarm6_leap_hand")
    root = robot.desc.root
    assert set(parents) >= set(robot.links) - {root}  # every link of the URDF placed, so the URDF layer draws it
    for frame in image_frames | wrist_frames | {"palm_lower"}:
        seen = frame
        for _ in range(64):
            if seen == root:
                break
            seen = parents[seen]  # a KeyError here: the frame hangs outside the tree
        assert seen == root, frame
    cam = next(tr for tr in tf[-1].transforms if tr.child == "cam_front")
    forward = quat_to_matrix(cam.rotation)[:, 2]  # the optical axis points at the rig's look_at
    aim = np.array([0.30, 0.0, 0.20]) - np.array([1.55, 0.50, 0.95])
    assert np.allclose(forward, aim / np.linalg.norm(aim), atol=1e-9)
    assert np.allclose(cam.translation, [1.55, 0.50, 0.95])


def test_frames_tables_are_checked():
    base = default_rig_path().read_text()
    with pytest.raises(ConfigError, match=r"\[frames.cam_side\]: names no camera of this rig"):
        load_rig_text(base + '\n[frames.cam_side]\nxyz = [0.0, 0.0, 1.0]\n', "r.toml")
    with pytest.raises(ConfigError, match="give rpy or look_at, not both"):
        load_rig_text(
            base.replace("look_at = [0.30, 0.0, 0.20]", "look_at = [0.3, 0.0, 0.2]\nrpy = [0.0, 0.0, 0.0]"), "r.toml"
        )
