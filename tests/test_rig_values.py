"""Rig values that no device or robot could follow are refused when the rig loads, naming the file, the
table and the key: NaN or inverted workspace bounds, sensor frames far away or in degrees, motion limits
looser than the robot's, transport delays and clock drifts no device has."""

from __future__ import annotations

import re

import pytest

from teleprev.errors import ConfigError
from teleprev.rig import default_rig_path, load_rig
from tests.helpers.cli import teleprev


def rig_with(tmp_path, table: str, line: str):
    """The default sim rig with `line` added at the top of [table] (later keys of the same name removed)."""
    text = default_rig_path().read_text()
    key = line.split("=")[0].strip()
    head, _, rest = text.partition(f"[{table}]")
    body, nxt, tail = rest.partition("\n[")
    body = re.sub(rf"(?m)^{re.escape(key)}\s*=.*$", "", body)
    path = tmp_path / "rig.toml"
    path.write_text(f"{head}[{table}]\n{line}{body}{nxt}{tail}")
    return path


@pytest.mark.parametrize(
    "table, line, where, said",
    [
        ("pipeline", "workspace_min = [0.80, -0.45, 0.05]", "[pipeline]", "workspace_min must be below workspace_max"),
        (
            "pipeline",
            "workspace_max = [nan, 0.45, 0.65]",
            "[pipeline].workspace_max[0]",
            "expected a finite number, got nan",
        ),
        (
            "pipeline",
            "arm_acceleration = 1e308",
            "[pipeline].arm_acceleration",
            "looser than the robot's own limit (10",
        ),
        ("pipeline", "arm_jerk = inf", "[pipeline].arm_jerk", "expected a finite number, got inf"),
        (
            "pipeline",
            "arm_tcp_speed = 1.2",
            "[pipeline].arm_tcp_speed",
            "1.2 m/s is looser than the robot's own limit (1,",
        ),
        (
            "pipeline",
            "hand_acceleration = 500.0",
            "[pipeline].hand_acceleration",
            "looser than the robot's own limit (200",
        ),
        ("pipeline", "wrist_scale = 0.0", "[pipeline]", "wrist_scale must be in (0, 10]"),
        ("frames.cam_front", "xyz = [1e300, 0.5, 0.95]", "[frames.cam_front]", "xyz must be within ±100 m"),
        ("frames.cam_front", "look_at = [nan, 0.0, 0.2]", "[frames.cam_front].look_at[0]", "expected a finite number"),
        ("frames.suit", "rpy = [0.0, 90.0, 0.0]", "[frames.suit]", "rpy is in radians"),
        (
            "devices.glove",
            "clock_drift_ppm = nan",
            "[devices.glove].clock_drift_ppm",
            "expected a finite number, got nan",
        ),
        ("devices.glove", "latency_ms = 1e12", "[devices.glove]", "latency_ms must be in [0, 1000] ms"),
        ("devices.cam_front", "clock_offset_s = 1e15", "[devices.cam_front]", "clock_offset_s must be within"),
    ],
)
def test_refused_at_load_naming_file_table_and_key(tmp_path, table, line, where, said):
    path = rig_with(tmp_path, table, line)
    with pytest.raises(ConfigError) as exc:
        load_rig(path)
    assert f"{path} {where}" in str(exc.value) and said in str(exc.value), str(exc.value)


def test_a_tighter_limit_is_taken_and_a_robot_the_table_lacks_has_a_bound(tmp_path):
    assert load_rig(rig_with(tmp_path, "pipeline", "arm_acceleration = 8.0")).pipeline.arm_acceleration == 8.0
    from teleprev.pipeline.config import PipelineConfig
    from teleprev.rig import RigSection, _check_motion_limits

    unknown = RigSection(robot="my_arm", end_effector="parallel_gripper")
    _check_motion_limits(unknown, PipelineConfig(arm_acceleration=50.0, arm_jerk=5000.0), "rig.toml")
    with pytest.raises(
        ConfigError, match=r"rig.toml \[pipeline\].arm_acceleration: 1000 rad/s² is more than any robot"
    ):
        _check_motion_limits(unknown, PipelineConfig(arm_acceleration=1000.0), "rig.toml")
    _check_motion_limits(unknown, PipelineConfig(arm_tcp_speed=3.0), "rig.toml")
    with pytest.raises(ConfigError, match=r"rig.toml \[pipeline\].arm_tcp_speed: 9 m/s is more than any robot"):
        _check_motion_limits(unknown, PipelineConfig(arm_tcp_speed=9.0), "rig.toml")


def test_record_says_so_in_one_line_before_any_device_opens(tmp_path):
    path = rig_with(tmp_path, "devices.glove", "latency_ms = 1e12")
    run = teleprev("record", path, "--duration", "5", cwd=tmp_path)
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert run.returncode == 2 and len(lines) == 1 and "latency_ms must be in [0, 1000] ms" in lines[0], run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]  # no session file
