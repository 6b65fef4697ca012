"""The default rigs load, build their devices, and bad sim settings are reported clearly."""

import pytest

from teleprev.clock import SessionClock
from teleprev.errors import ConfigError
from teleprev.rig import default_rig_path, load_rig


@pytest.mark.parametrize(
    "name, robot, end_effector, hand_joints",
    [
        ("sim", "xarm6_leap_hand", "leap_hand", tuple(str(i) for i in range(16))),
        ("sim_gripper", "xarm6_parallel_gripper", "parallel_gripper", ("gripper",)),
        ("sim_vacuum", "xarm6_vacuum", "vacuum", ("vacuum",)),
    ],
)
def test_rig_loads_and_builds_its_devices(name, robot, end_effector, hand_joints):
    rig = load_rig(default_rig_path().parent / f"{name}.toml")
    assert (rig.rig.name, rig.rig.robot, rig.rig.end_effector, rig.rig.task) == (
        name,
        robot,
        end_effector,
        "pick_place",
    )
    assert {d.kind: d.plugin for d in rig.devices.values()} == {
        "glove": "sim.glove", "suit": "sim.suit", "camera": "sim.camera", "arm": "sim.arm", "hand": "sim.hand"}
    rig.require("glove", "suit", "camera", "arm", "hand")
    ctx = rig.device_context(SessionClock())
    devices = {n: e.cls(n, e.settings, ctx) for n, e in rig.devices.items()}
    topics = {n: [s.topic for s in d.streams()] for n, d in devices.items()}
    assert topics == {
        "glove": ["/glove/glove/hand"],
        "suit": ["/suit/suit/wrist"],
        "cam_front": ["/camera/cam_front/image"],
        "arm": ["/arm/arm/state"],
        "hand": ["/hand/hand/state"],
    }
    assert devices["hand"].joint_names == hand_joints
    assert devices["arm"].joint_names == tuple(f"joint{i}" for i in range(1, 7))


def test_default_rig_is_the_sim_rig():
    assert load_rig().rig.name == "sim"


@pytest.mark.parametrize(
    "line, match",
    [
        ("rate_hz = 0.0", r"\[devices.glove\]: rate_hz must be in \(0, 2000\]"),
        ('task = "juggle"', r"\[devices.glove\]: task must be '', 'cycle' or one of pick_place"),
        ("rate = 10", r"\[devices.glove\]: unknown key 'rate'"),
        ('noise_rad = "low"', r"\[devices.glove\].noise_rad: expected a number"),
    ],
)
def test_bad_glove_settings_name_the_table_and_key(tmp_path, line, match):
    rig = tmp_path / "rig.toml"
    rig.write_text(f'[devices.glove]\nplugin = "sim.glove"\n{line}\n')
    with pytest.raises(ConfigError, match=match):
        load_rig(rig)
