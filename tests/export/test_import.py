"""teleprev import: foreign recordings written by other people's writers (rosbags: ROS 2 MCAP and rosbag2
sqlite3; the mcap library with Foxglove's protobuf schemas) into LeRobot datasets, loaded back with
lerobot's own LeRobotDataset."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from teleprev.errors import ConfigError, SessionError
from teleprev.export.foreign.config import load_import_recipe
from teleprev.export.foreign.run import import_files
from teleprev.export.foreign.samples import (
    ARM,
    T0_NS,
    ForeignSpec,
    gripper_q,
    ros2_mcap_file,
    write_foxglove_mcap,
    write_ros2,
)
from teleprev.export.recipe import load_recipe
from teleprev.export.synthetic import arm_q, read_frame_code
from tests.helpers.cli import teleprev

ROOT = Path(__file__).resolve().parents[2]
TWO = ForeignSpec(episodes=((0.0, 2.0), (3.0, 5.0)))


def _recipe(tmp_path: Path, imports: str, features: str, export: str = "fps = 30") -> Path:
    path = tmp_path / "r.toml"
    path.write_text(f"[import]\n{imports}\n[export]\n{export}\nmin_episode_s = 0.5\n{features}")
    return path


ROS_FEATURES = """
[[feature]]
name = "observation.state"
streams = ["/joint_states"]
[[feature]]
name = "action"
streams = ["/joint_states"]
timing = "next"
[[feature]]
name = "observation.pose"
streams = ["/ee_pose", "/tf/tool0"]
[[feature]]
name = "observation.images.front"
streams = ["/camera/front/image"]
"""


def _load(root: Path, repo: str = "t/x"):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(repo, root=root, video_backend="pyav")


def _column(ds, name: str) -> np.ndarray:
    return np.stack([np.asarray(v) for v in ds.hf_dataset[name]])


def test_ros2_mcap_events_resampled_to_one_fps_with_derived_actions(tmp_path):
    bag = ros2_mcap_file(write_ros2(tmp_path / "bag", TWO, storage="mcap"))
    recipe = load_import_recipe(
        _recipe(
            tmp_path,
            'episodes = "events"\nevents_topic = "/episode_events"\n'
            'task = "pick up the cube and place it in the bowl"\nrobot_type = "xarm6"\n'
            '[import.joints]\n"/joint_states" = ["joint1","joint2","joint3","joint4","joint5",'
            '"joint6","gripper"]',
            ROS_FEATURES,
        )
    )
    report = import_files([bag], recipe, "t/x", tmp_path / "out")
    assert report.total_episodes == 2
    umask = os.umask(0o022)
    os.umask(umask)
    modes = {p.relative_to(tmp_path).as_posix(): oct(p.stat().st_mode & 0o777) for p in (tmp_path / "out").rglob("*")}
    assert set(modes.values()) <= {oct(0o666 & ~umask), oct(0o777 & ~umask)}, modes  # readable as usual
    ds = _load(tmp_path / "out")
    assert ds.meta.robot_type == "xarm6" and ds.fps == 30
    assert list(ds.meta.tasks.index) == ["pick up the cube and place it in the bowl"]
    names = ds.meta.features["observation.state"]["names"]
    assert names == [f"joint_states.{j}" for j in ARM] + ["joint_states.gripper"]
    assert ds.meta.features["observation.pose"]["names"][:3] == ["ee_pose.x", "ee_pose.y", "ee_pose.z"]
    state, action, ep = _column(ds, "observation.state"), _column(ds, "action"), _column(ds, "episode_index")
    stamps = _column(ds, "timestamp")
    # each episode runs about 2 s at 30 fps; the two are apart (the silence between them is not bridged)
    assert 55 <= (ep == 0).sum() <= 61 and 55 <= (ep == 1).sum() <= 61
    # the state is the latest joint state at or before the frame: within one 100 Hz sample of arm_q there
    for e, start in ((0, 0.0), (1, 3.0)):
        rows = np.flatnonzero(ep == e)
        # frames start on a camera frame at or after "start" (the first one is trimmed when the merged joint
        # state is not complete yet: the gripper's first message comes 0.5 ms after the arm's)
        errors = []
        for first_camera in (start, start + 1 / 30):
            t = first_camera + stamps[rows].reshape(-1)
            errors.append(np.abs(state[rows] - np.c_[arm_q(t), gripper_q(t)]).max())
        assert min(errors) < 0.3 * 2 * np.pi * 0.2 * 0.011 + 1e-3
        # the derived action is the next frame's state
        assert np.allclose(action[rows[:-1]], state[rows[1:]])
    # the pose features: PoseStamped and the same pose from /tf agree
    pose = _column(ds, "observation.pose")
    assert np.allclose(pose[:, :7], pose[:, 7:], atol=1e-6)
    frame = ds[int(np.flatnonzero(ep == 1)[0])]
    assert tuple(frame["observation.images.front"].shape) == (3, 120, 160)
    assert frame["task"] == "pick up the cube and place it in the bowl"


def test_rosbag2_sqlite_zstd_with_raw_images_split_at_gaps(tmp_path):
    folder = write_ros2(tmp_path / "bag", ForeignSpec(episodes=((0.0, 1.5), (3.0, 4.5)), raw_images=True, events=False),
                        storage="sqlite3", zstd=True)
    assert (folder / "bag.db3").is_file() and "zstd" in (folder / "metadata.yaml").read_text()
    recipe = load_import_recipe(_recipe(tmp_path, 'episodes = "gaps"\ngap_s = 0.5\ntask = "wave"', ROS_FEATURES,
                                        export="fps = 0"))
    report = import_files([folder], recipe, "t/x", tmp_path / "out")
    assert report.total_episodes == 2 and report.fps == 30
    ds = _load(tmp_path / "out")
    assert ds.meta.robot_type == "unknown"
    # raw bgr8 images arrive as RGB: the frame number drawn into each camera frame reads back in order
    ep = _column(ds, "episode_index")
    first = [int(np.flatnonzero(ep == e)[0]) for e in (0, 1)]
    codes = []
    for i in first:
        img = (ds[i]["observation.images.front"].permute(1, 2, 0).numpy() * 255).astype(np.uint8)
        codes.append(read_frame_code(img))
    assert codes[0] in (0, 1) and codes[1] in (45, 46)  # 1.5 s x 30 frames before the second demonstration
    # without [import.joints] or a URDF, the joints are as recorded: the arm's, then the gripper's
    assert ds.meta.features["observation.state"]["names"][-1] == "joint_states.gripper"


def test_foxglove_mcap_without_episode_events_imports_as_one_episode(tmp_path):
    path = write_foxglove_mcap(tmp_path / "fox.mcap", ForeignSpec(episodes=((0.0, 2.0),)))
    features = """
[[feature]]
name = "observation.state"
streams = ["/joints"]
[[feature]]
name = "action"
streams = ["/joints"]
timing = "next"
[[feature]]
name = "observation.images.front"
streams = ["/camera/front"]
"""
    recipe_path = _recipe(
        tmp_path, f'episodes = "file"\ntask = "reach"\nurdf = "{ROOT / "urdf" / "xarm6.urdf"}"', features
    )
    recipe = load_import_recipe(recipe_path)
    assert recipe.urdf_joints == ARM and recipe.robot_type  # joint names (and the robot) from the URDF
    out = teleprev("import", path, "--recipe", recipe_path, "--repo-id", "t/fox", "--root", tmp_path / "out", "--json")
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    assert summary["total_episodes"] == 1 and 55 <= summary["total_frames"] <= 61
    ds = _load(tmp_path / "out", "t/fox")
    # the URDF's joints in its order: the recorded gripper, which the URDF lacks, is not a feature
    assert ds.meta.features["observation.state"]["names"] == [f"joints.{j}" for j in ARM]
    t = _column(ds, "timestamp").reshape(-1)
    state = _column(ds, "observation.state")
    assert np.abs(state[:, :6] - arm_q(t)).max() < 0.01


def test_bad_import_recipes_and_files_say_what_is_wrong(tmp_path):
    bag = write_ros2(tmp_path / "bag", ForeignSpec(episodes=((0.0, 1.0),)), storage="sqlite3")
    missing = load_import_recipe(
        _recipe(tmp_path, '[import.joints]\n"/joint_states" = ["joint1", "elbow"]', ROS_FEATURES)
    )
    with pytest.raises(SessionError, match=r"\[import.joints\] /joint_states: no joints \['elbow'\]"):
        import_files([bag], missing, "t/x", tmp_path / "out1")
    no_topic = load_import_recipe(_recipe(tmp_path, "", '[[feature]]\nname = "observation.state"\nstreams = ["/arm"]'))
    with pytest.raises(SessionError, match=r"no topic /arm in this file \(its topics: /camera/front/image, /ee_pose, "
                                           r"/episode_events, /joint_states, /tf, /tf/tool0\)"):
        import_files([bag], no_topic, "t/x", tmp_path / "out2")
    with pytest.raises(ConfigError, match='episodes = "events" needs events_topic'):
        load_import_recipe(_recipe(tmp_path, 'episodes = "events"', ROS_FEATURES))
    with pytest.raises(ConfigError, match="use it with `teleprev import`"):
        load_recipe(ROOT / "datasets" / "imports" / "ros2_arm.toml")
    with pytest.raises(SessionError, match="not a rosbag2 recording"):
        import_files([tmp_path], missing, "t/x", tmp_path / "out3")
    assert not (tmp_path / "out1").exists() and not (tmp_path / "out2").exists()


def test_header_stamps_on_another_clock_are_refused_until_log_time_is_chosen(tmp_path):
    bag = write_ros2(tmp_path / "bag", ForeignSpec(episodes=((0.0, 1.5),), header_offset_s=-3600.0), storage="mcap")
    header = load_import_recipe(_recipe(tmp_path, "", ROS_FEATURES))
    with pytest.raises(SessionError, match=r'header stamps are -3600.0 s from .* set \[import\] timestamps = "log"'):
        import_files([bag], header, "t/x", tmp_path / "out1")
    logged = load_import_recipe(_recipe(tmp_path, 'timestamps = "log"', ROS_FEATURES))
    report = import_files([bag], logged, "t/x", tmp_path / "out2")
    assert report.total_episodes == 1 and 40 <= report.total_frames <= 46


def test_foxglove_joint_states_follow_the_recipes_joints_and_order(tmp_path):
    """As the ROS path does: [import.joints] picks and orders them (recorded: the arm, then the gripper)."""
    from teleprev.export.foreign.foxglove import FoxgloveReader

    path = write_foxglove_mcap(tmp_path / "fox.mcap", ForeignSpec(episodes=((0.0, 0.5),)))
    pick = '"/joints" = ["gripper", "joint6", "joint1"]'
    state = '[[feature]]\nname = "observation.state"\nstreams = ["/joints"]'
    recipe = load_import_recipe(_recipe(tmp_path, f'episodes = "file"\n[import.joints]\n{pick}', state))
    reader = FoxgloveReader(path, recipe)
    try:
        first = next(iter(reader.messages(["/joints"])))
    finally:
        reader.close()
    t = (first.payload.stamp_ns - T0_NS) / 1e9
    assert first.payload.names == ("gripper", "joint6", "joint1")
    np.testing.assert_allclose(first.payload.positions, [gripper_q(t), arm_q(t)[5], arm_q(t)[0]], atol=1e-9)
    missing = load_import_recipe(_recipe(tmp_path, 'episodes = "file"\n[import.joints]\n"/joints" = ["joint7"]', state))
    reader = FoxgloveReader(path, missing)
    try:
        with pytest.raises(SessionError, match=r"\[import.joints\] /joints: no joints \['joint7'\]"):
            reader.joint_names("/joints")
    finally:
        reader.close()


def test_a_bag_that_stores_no_message_definitions_reads_with_the_standard_ones(tmp_path):
    """ROS 2 Humble's sqlite3 bags store no message definitions; an empty one used to fail with the rosbags
    library's hint to its own API ("Instantiate AnyReader with a default_typestore")."""
    import sqlite3

    def without_definitions(name, spec):
        bag = write_ros2(tmp_path / name, spec, storage="sqlite3")
        with sqlite3.connect(next(bag.glob("*.db3"))) as db:
            db.execute("delete from message_definitions")
        return bag

    state = '[[feature]]\nname = "observation.state"\nstreams = ["/joint_states"]\n'
    recipe = load_import_recipe(_recipe(tmp_path, 'episodes = "file"\nurdf = "xarm6"', state + state.replace(
        "observation.state", "action") + 'timing = "next"\n'))
    report = import_files([without_definitions("humble", ForeignSpec(episodes=((0.0, 1.0),)))], recipe, "t/h",
                          tmp_path / "out")
    assert report.total_episodes == 1 and report.total_frames > 20
    with pytest.raises(SessionError) as exc:  # recorded, but nothing was published
        import_files(
            [without_definitions("empty", ForeignSpec(episodes=((0.0, 0.0),), events=False))],
            recipe,
            "t/e",
            tmp_path / "e",
        )
    assert "typestore" not in str(exc.value) and "holds no messages" in str(exc.value), str(exc.value)
