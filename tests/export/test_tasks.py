"""Tasks reach LeRobot as natural-language instructions (the rig's [tasks], record --task-text), while the
session keeps the task id."""

from __future__ import annotations

import pytest

from teleprev.export.recipe import load_recipe
from teleprev.export.run import ExportOptions, export
from teleprev.session.reader import SessionReader
from tests.helpers.sessions import record_sim


@pytest.mark.parametrize("task_text", ["", "put the red cube in the blue bowl"])
def test_the_dataset_gets_the_instruction_and_the_session_keeps_the_id(tmp_path, task_text):
    session = tmp_path / "s.mcap"
    record_sim(session, seconds=2.5, engage_after=0.5, task="pick_place", task_text=task_text)  # long enough under load
    with SessionReader(session) as r:
        assert [e.task for e in r.episodes()] == ["pick_place"]
        assert r.metadata["session"]["task"] == "pick_place"
        want = task_text or "pick up the cube and place it in the bowl"  # rigs/sim.toml [tasks]
        assert r.metadata["tasks"]["pick_place"] == want and r.metadata["tasks"]["pour"] == "pour the cup into the bowl"
    export(ExportOptions([session], "t/tasks", tmp_path / "out", load_recipe()))
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("t/tasks", root=tmp_path / "out", video_backend="pyav")
    assert list(ds.meta.tasks.index) == [want]
    assert ds[0]["task"] == want
