"""`teleprev audit DATASET --config <bimanual rig>`: each side's actions against that side's own limits, the
joints found by LeRobot's bimanual names (left_arm.joint1 ...) or, unnamed, by position (left first)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from teleprev.evaluation.audit import audit_path
from tests.bimanual.test_record_export import expected_names
from tests.helpers.cli import teleprev

RIGS = Path(__file__).parents[2] / "rigs"
BIMANUAL = RIGS / "sim_bimanual.toml"


def _dataset(root: Path, names: list[str], jump_col: int | None, jump: float = 0.05) -> Path:
    """A LeRobot dataset of 44 actions at 30 fps, moving slowly; `jump_col`: `jump` rad at frame 20 there."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset.create("lab/bi", fps=30, features={"action": {"dtype": "float32", "shape": (44,),
                                                                      "names": names}},
                               root=root, robot_type="bi_xarm6", use_videos=False)
    for i in range(40):
        a = np.full(44, 0.2, np.float32)  # the hands' joints
        a[0:6] = a[22:28] = [0.01 * np.sin(i / 10.0), -0.27, -0.11, 0.0, -0.85, -1.571]  # the arms, near home
        if jump_col is not None and i >= 20:
            a[jump_col] += jump
        ds.add_frame({"action": a, "task": "t"})
    ds.save_episode()
    ds.finalize()
    return root


def test_each_side_is_matched_by_name_and_a_jump_fails_its_own_stream(tmp_path):
    names = expected_names()
    smooth = audit_path(_dataset(tmp_path / "smooth", names, None), BIMANUAL)
    assert [s.topic for s in smooth.streams] == ["action[left arm]", "action[left end effector]", "action[right arm]",
                                                 "action[right end effector]"]
    assert smooth.ok and smooth.note == "" and all(s.commands == 40 for s in smooth.streams)
    # the left arm's jump fails the left arm alone (its column by name, the left side's limits)
    jumpy = _dataset(tmp_path / "jumpy", names, names.index("left_arm.joint3"))
    report = audit_path(jumpy, BIMANUAL)
    assert [bool(s.violations) for s in report.streams] == [True, False, False, False]
    assert report.streams[0].ratios["accel"] > 3  # 2 x 1.5 rad/s over 2 frames = 45 rad/s^2, against 10
    out = tmp_path / "audit.json"
    run = teleprev("audit", tmp_path / "smooth", jumpy, "--config", BIMANUAL, "--json", out, columns=100)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "action[left arm]: accel" in " ".join(run.stdout.split())  # the stream's name, not eaten as markup
    assert [d["ok"] for d in json.loads(out.read_text())] == [True, False]


def test_unnamed_actions_are_matched_by_position_left_first(tmp_path):
    # the right hand's joint "10": 0.5 rad in a frame is 15 rad/s, past the LEAP Hand's 8.48
    root = _dataset(tmp_path / "unnamed", [f"motor_{i}" for i in range(44)], 22 + 6 + 10, jump=0.5)
    report = audit_path(root, BIMANUAL)
    assert "by position" in report.note
    assert [bool(s.violations) for s in report.streams] == [False, False, False, True]
    assert report.streams[3].ratios["speed"] > 1.5


def test_a_single_arm_rig_cannot_audit_a_bimanual_dataset(tmp_path):
    root = _dataset(tmp_path / "bi", expected_names(), None)
    run = teleprev("audit", root, "--config", RIGS / "sim.toml")
    assert run.returncode != 0
    assert "info.json: the action's 44 names ['left_arm.joint1'" in " ".join((run.stdout + run.stderr).split())
