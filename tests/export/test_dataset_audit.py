"""`teleprev audit DATASET`: a LeRobot dataset's `action` column against a rig's limits, for teleprev's
own exports (joints by name) and anyone's (joints by position)."""

import json
from pathlib import Path

import numpy as np
import pytest

from teleprev.evaluation.audit import audit_path
from tests.helpers.cli import teleprev
from tests.helpers.sessions import record_sim

RIGS = Path(__file__).parents[2] / "rigs"


def _cli(*args):
    return teleprev(*args, columns=80)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("audit_ds")
    session = tmp / "s.mcap"
    record_sim(session, "sim_gripper.toml", seconds=3.0, engage_after=0.8)
    root = tmp / "ds"
    run = _cli("export", session, "--repo-id", "lab/audit", "--root", root)
    assert run.returncode == 0, run.stdout + run.stderr
    return root


def test_our_export_is_matched_by_name_and_measured_as_lerobot_loads_it(exported):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    report = audit_path(exported, RIGS / "sim_gripper.toml")
    arm, hand = report.streams
    assert arm.commands > 30 and hand.commands == arm.commands
    assert report.note == "" and arm.position_outside == 0 and hand.position_outside == 0
    # the same figures from the dataset as lerobot loads it (actions at the frames' timestamps)
    ds = LeRobotDataset("lab/audit", root=exported, video_backend="pyav")
    names = ds.meta.features["action"]["names"]
    cols = [names.index(f"arm.joint{i}") for i in range(1, 7)]
    rows = [ds.hf_dataset[i] for i in range(len(ds.hf_dataset))]
    t = np.array([float(r["timestamp"]) for r in rows])
    q = np.array([np.asarray(r["action"], dtype=float)[cols] for r in rows])
    v = np.diff(q, axis=0) / np.diff(t)[:, None]
    a = 2 * np.diff(v, axis=0) / (t[2:] - t[:-2])[:, None]
    assert np.isclose(arm.speed_max, np.abs(v).max(), rtol=1e-4) and np.isclose(
        arm.accel_max, np.abs(a).max(), rtol=1e-4
    )
    # An action is the first command sent in its frame, stamped with the frame's time: up to one command
    # period (8 ms) of jitter on 33 ms frames, which divided differences amplify, so no bound on the ratio.
    assert 0 < arm.ratios["accel"]


def _foreign(root: Path, jump: float) -> Path:
    """Someone else's dataset: 7 unnamed motors (an xArm6 and a gripper) at 30 fps; `jump` rad on motor 0."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    features = {"action": {"dtype": "float32", "shape": (7,), "names": [f"motor_{i}" for i in range(7)]}}
    ds = LeRobotDataset.create(
        "someone/else", fps=30, features=features, root=root, robot_type="xarm6", use_videos=False
    )
    for i in range(40):
        a = np.zeros(7, np.float32)
        a[0] = 0.01 * np.sin(i / 10.0) + (jump if i >= 20 else 0.0)
        a[6] = 0.02
        ds.add_frame({"action": a, "task": "t"})
    ds.save_episode()
    ds.finalize()
    return root


def test_someone_elses_dataset_matched_by_position_and_a_jump_fails_the_cli(tmp_path):
    smooth = _foreign(tmp_path / "smooth", 0.0)
    jumpy = _foreign(tmp_path / "jumpy", 0.05)
    report = audit_path(smooth, RIGS / "sim_gripper.toml")
    assert report.ok and "by position" in report.note
    out = tmp_path / "audit.json"
    run = _cli("audit", smooth, jumpy, "--config", RIGS / "sim_gripper.toml", "--json", out)
    assert run.returncode == 1, run.stdout + run.stderr
    data = json.loads(out.read_text())
    assert [d["ok"] for d in data] == [True, False]
    assert (
        data[1]["streams"][0]["ratios"]["accel"] > 3
    )  # 0.05 rad in one frame at 30 fps: 2 x 1.5 rad/s over 2 frames = 45 rad/s^2


def test_a_dataset_needs_a_rig_and_matching_joints(exported, tmp_path):
    run = _cli("audit", exported)
    assert run.returncode != 0 and "--config" in run.stdout + run.stderr
    run = _cli("audit", exported, "--config", RIGS / "sim.toml")  # a LEAP rig: 22 joints, the export has 7
    assert run.returncode != 0
    assert "cannot be matched" in run.stdout + run.stderr and "info.json" in run.stdout + run.stderr
