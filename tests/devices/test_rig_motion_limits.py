"""An arm's or hand's own motion-limit settings (max_velocity, max_acceleration, max_jerk of any plugin) are
checked against the robot's physical numbers when the rig loads: one line naming the file, the device's
table, the key and the allowed range. `max_jerk = 1e308` in [devices.arm] was accepted, and a sim arm so
set never faults on a command stream no xArm takes."""

from __future__ import annotations

import re

import pytest

from teleprev.errors import ConfigError
from teleprev.rig import default_rig_path, load_rig
from tests.helpers.cli import teleprev
from tests.test_rig_values import rig_with

RIGS = default_rig_path().parent


@pytest.mark.parametrize("table, line, allowed", [
    ("devices.arm", "max_jerk = 1e308", "max_jerk must be in (0, 500] rad/s³"),
    ("devices.arm", "max_jerk = 600.0", "max_jerk must be in (0, 500] rad/s³"),
    ("devices.arm", "max_acceleration = 10.5", "max_acceleration must be in (0, 10] rad/s²"),
    ("devices.arm", "max_velocity = 3.5", "max_velocity must be in [0, 3.14] rad/s (0: the URDF's)"),
    ("devices.hand", "max_velocity = 9.0", "max_velocity must be in [0, 8.48] rad/s (0: the URDF's)"),
])
def test_a_device_limit_past_the_robots_is_one_line(tmp_path, table, line, allowed):
    path = rig_with(tmp_path, table, line)
    key = line.split("=")[0].strip()
    with pytest.raises(ConfigError) as caught:
        load_rig(path)
    assert str(caught.value).startswith(f"{path} [{table}].{key}: ")
    assert allowed in str(caught.value)
    ran = teleprev("audit", RIGS.parent / "tests" / "fixtures" / "sim_v2.mcap", "--config", path)
    assert ran.returncode == 2 and ran.stderr.strip() == f"error: {caught.value}", ran.stderr


def test_every_arm_plugin_is_checked_and_the_shipped_rigs_pass(tmp_path):
    """The xArm plugin's limits are the same family; the gripper's speed is in m/s, from its URDF."""
    text = default_rig_path().read_text()
    xarm = re.sub(r"(?s)\[devices\.arm\].*?(?=\n\[)", '[devices.arm]\nplugin = "xarm.arm"\nhost = "10.0.0.9"\n'
                  "max_jerk = 501.0\n", text)
    path = tmp_path / "xarm.toml"
    path.write_text(xarm)
    with pytest.raises(ConfigError, match=re.escape("[devices.arm].max_jerk: 501 is outside the robot's range")):
        load_rig(path)
    gripper = (RIGS / "sim_gripper.toml").read_text().replace("max_velocity = 0.0               # m/s",
                                                              "max_velocity = 0.2  # m/s")
    (tmp_path / "gripper.toml").write_text(gripper)
    with pytest.raises(ConfigError, match=r"max_velocity must be in \[0, 0.\d+\] m/s"):
        load_rig(tmp_path / "gripper.toml")
    for rig in sorted(RIGS.glob("*.toml")):
        load_rig(rig)
