"""A dataset whose `action` holds a NaN (or inf) is refused in one line naming the row, episode and joint:
by `audit` (which measured the finite ones and said "audit passed") and by `replay --smooth` (whose
jerk-limited generator raised RuckigError). The dataset is written as LeRobot lays one out (meta/info.json,
data/*.parquet), without importing lerobot, so that the commands answer in a second."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.cli.test_mistakes import one_line
from tests.helpers.cli import teleprev

RIG = Path(__file__).parents[2] / "rigs" / "sim_gripper.toml"


def dataset(root: Path, bad: float, row: int = 10, frames: int = 40) -> Path:
    """Someone's dataset, 7 unnamed motors (an xArm6 and a gripper) at 30 fps, `bad` at motor 2 in `row`."""
    names = [f"motor_{i}" for i in range(7)]
    (root / "meta").mkdir(parents=True)
    info = {"codebase_version": "v3.0", "fps": 30, "robot_type": "xarm6",
            "features": {"action": {"dtype": "float32", "shape": [7], "names": names},
                         "timestamp": {"dtype": "float32", "shape": [1], "names": None},
                         "episode_index": {"dtype": "int64", "shape": [1], "names": None}}}
    (root / "meta" / "info.json").write_text(json.dumps(info))
    action = np.zeros((frames, 7), np.float32)
    action[:, 0] = 0.01 * np.sin(np.arange(frames) / 10.0)
    action[:, 6] = 0.02
    action[row, 2] = bad
    (root / "data" / "chunk-000").mkdir(parents=True)
    table = pa.table({"action": pa.array(list(action), type=pa.list_(pa.float32(), 7)),
                      "timestamp": pa.array(np.arange(frames, dtype=np.float32) / 30),
                      "episode_index": pa.array(np.zeros(frames, np.int64))})
    pq.write_table(table, root / "data" / "chunk-000" / "file-000.parquet")
    return root


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_audit_refuses_a_not_finite_action(tmp_path, bad):
    run = teleprev("audit", dataset(tmp_path / "ds", bad), "--config", RIG)
    assert run.returncode != 0 and "audit passed" not in run.stdout, run.stdout
    line = one_line(run)
    assert f"action 'motor_2' is {bad} in row 10 (episode 0" in line and "file-000.parquet" in line, line


def test_audit_of_a_finite_one_still_passes(tmp_path):
    run = teleprev("audit", dataset(tmp_path / "ds", 0.0), "--config", RIG)
    assert run.returncode == 0 and "audit passed" in run.stdout, run.stdout + run.stderr


def test_replay_smooth_refuses_it_before_playing(tmp_path):
    run = teleprev("replay", dataset(tmp_path / "ds", float("nan")), "--episode", "0", "--config", RIG, "--smooth",
                   "--no-preview")
    assert run.returncode == 2
    assert "action 'motor_2' is nan in row 10" in one_line(run)
