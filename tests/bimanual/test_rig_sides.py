"""Rigs with [sides.left] and [sides.right]: parsed and checked; single-arm rigs read as before."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

from teleprev.bimanual import side_calibration
from teleprev.errors import ConfigError
from teleprev.rig import load_rig, parse_rig, side_rig

ROOT = Path(__file__).resolve().parents[2]
BIMANUAL = ROOT / "rigs" / "sim_bimanual.toml"


def _data() -> dict:
    return tomllib.loads(BIMANUAL.read_text())


def test_sim_bimanual_rig_has_two_sides():
    rig = load_rig(BIMANUAL)
    assert rig.bimanual and list(rig.sides) == ["left", "right"]
    left, right = rig.sides["left"], rig.sides["right"]
    assert left.robot == "xarm6_leap_hand_left" and left.effector.hand_urdf == "leap_hand_left"
    assert right.robot == "xarm6_leap_hand" and right.effector.hand_urdf == "leap_hand_right"
    assert left.devices == {"arm": "arm_left", "hand": "hand_left", "glove": "glove_left", "suit": "suit_left"}
    one = side_rig(rig, "left")
    assert one.rig.robot == "xarm6_leap_hand_left" and one.effector.hand_urdf == "leap_hand_left"
    assert set(one.devices) == {"arm_left", "hand_left", "glove_left", "suit_left"}
    assert left.prefixed("arm.joint1") == "left_arm.joint1"


@pytest.mark.parametrize("rig", sorted(p.name for p in (ROOT / "rigs").glob("*.toml") if p.name != "sim_bimanual.toml"))
def test_single_arm_rigs_have_no_sides(rig):
    loaded = load_rig(ROOT / "rigs" / rig)
    assert not loaded.bimanual and loaded.sides == {}
    assert type(loaded).__name__ == "Rig"  # not a side's view


def test_a_side_tightens_its_own_limits():
    data = _data()
    data["sides"]["left"]["pipeline"] = {"arm_acceleration": 8.0}
    rig = parse_rig(data, BIMANUAL)
    assert rig.sides["left"].pipeline.arm_acceleration == 8.0
    assert rig.sides["right"].pipeline.arm_acceleration is None
    assert rig.sides["left"].pipeline.tcp_link == "palm_lower"  # the rig's [pipeline] underneath
    data["sides"]["left"]["pipeline"] = {"arm_acceleration": 1000.0}
    with pytest.raises(ConfigError, match=r"\[sides.left\].*arm_acceleration.*looser"):
        parse_rig(data, BIMANUAL)


def test_mount_yaw_turns_the_suit_into_the_side_base():
    data = _data()
    data["sides"]["left"]["mount_yaw"] = 0.5
    rig = parse_rig(data, BIMANUAL)
    assert side_calibration(rig, "left").calibration.suit_yaw == pytest.approx(-0.5)
    assert side_calibration(rig, "right").calibration.suit_yaw == 0.0
    data["sides"]["left"]["mount_yaw"] = 90.0
    with pytest.raises(ConfigError, match=r"\[sides.left\].*mount_yaw is in radians"):
        parse_rig(data, BIMANUAL)
    assert math.pi  # (radians)


@pytest.mark.parametrize("change, message", [
    (lambda d: d["sides"].pop("right"), r"\[sides\]: a bimanual rig needs both sides: add \[sides.right\]"),
    (lambda d: d["sides"].update(middle=dict(d["sides"]["left"])), r"unknown side 'middle'"),
    (lambda d: d["sides"]["left"].update(arm="arm_right"), r"\[sides.right\].arm: both sides name arm device"),
    (lambda d: d["sides"]["left"].update(arm="arm_middle"), r"\[sides.left\].arm: no device 'arm_middle'"),
    (lambda d: d["sides"]["left"].update(hand="arm_left"), r"\[sides.left\].hand: device 'arm_left' is a arm"),
    (lambda d: d["sides"]["left"].update(wrist="suit_left"), r"\[sides.left\]: unknown key 'wrist'"),
    (lambda d: d["sides"]["left"].update(robot="xarm9"), r"\[sides.left\].*no such robot 'xarm9'"),
    (lambda d: d["sides"]["left"].update(end_effector="vacuum", robot="xarm6_vacuum"),
     r"\[sides.left\].hand_urdf: hand_urdf is for an end effector with self-collision"),
])
def test_bad_sides_name_what_is_wrong(change, message):
    data = _data()
    change(data)
    if "hand_urdf" in message:
        data["sides"]["left"]["hand_urdf"] = "leap_hand_left"
    with pytest.raises(ConfigError, match=message):
        parse_rig(data, BIMANUAL)


def test_side_calibration_file_must_exist(tmp_path):
    text = BIMANUAL.read_text().replace('mount_yaw = 0.0\n', 'mount_yaw = 0.0\ncalibration = "nope.toml"\n', 1)
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"\[sides.left\].calibration: no such file"):
        load_rig(path)


def test_single_arm_commands_refuse_a_bimanual_rig_in_one_line():
    from teleprev.assembly import build_pipeline, motion_limits

    rig = load_rig(BIMANUAL)
    for build in (build_pipeline, motion_limits):
        with pytest.raises(ConfigError, match=r"sim_bimanual.toml: a bimanual rig .*not built for two sides yet"):
            build(rig)
    assert build_pipeline(side_rig(rig, "left")).effector.corrector.model.name == "leap_hand_left"


def test_a_camera_belongs_to_one_side_or_none():
    data = _data()
    data["devices"]["cam_right"] = {"plugin": "sim.camera", "width": 160, "height": 120}
    data["devices"]["cam_top"] = {"plugin": "sim.camera", "width": 160, "height": 120}
    data["sides"]["right"]["cameras"] = ["cam_right"]
    rig = parse_rig(data, BIMANUAL)
    assert "cam_right" in side_rig(rig, "right").devices and "cam_right" not in side_rig(rig, "left").devices
    assert "cam_top" in side_rig(rig, "left").devices and "cam_top" in side_rig(rig, "right").devices  # no side's
    data["sides"]["left"]["cameras"] = ["cam_right"]
    with pytest.raises(ConfigError, match=r"\[sides.right\].cameras: both sides name camera 'cam_right'"):
        parse_rig(data, BIMANUAL)
    data["sides"]["left"]["cameras"] = ["arm_left"]
    with pytest.raises(ConfigError, match=r"\[sides.left\].cameras\[0\]: 'arm_left' is not a camera device"):
        parse_rig(data, BIMANUAL)
