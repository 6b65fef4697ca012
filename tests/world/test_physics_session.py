"""Real sessions on the physics rig (rigs/sim_physics.toml), recorded through `teleprev record` and read back
from their MCAP files: the scenes the world ran (restorable layouts with their seed), each episode marked by
the world beside the operator's marks, the operator's mark winning, `export --only` choosing by the combined
mark, and the preview showing the outcome when an episode ends."""

from __future__ import annotations

import io
from types import SimpleNamespace

import pytest
from rich.console import Console

from teleprev import topics
from teleprev.live.record.cues import Cues
from teleprev.live.record.run import run_timed
from teleprev.live.record.schedule import EpisodeTimes
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.rig import default_rig_path
from teleprev.session.reader import SessionReader
from teleprev.world.layout import layout_from_record
from teleprev.world.places import SPOTS
from tests.helpers.cli import teleprev

PHYSICS_RIG = default_rig_path().parent / "sim_physics.toml"
# 2.5 s is too short for the simulated operator to put the cup on the target (its pick_place takes 6 s and
# more), so the world judges every episode a failure, and an operator's "y" is seen to override it.
EPISODE_S = 2.5


def _record(path, marks: str) -> SimpleNamespace:
    # One engaged episode per session is all these tests need (re-engages, which start from the command the
    # arm's controller holds wherever contact pushed the arm: tests/world/test_physics_eval.py).
    ran = teleprev("record", PHYSICS_RIG, "--out", path, "--episodes", "1", "--episode-time", EPISODE_S,
                   "--engage-after", "0.3", "--marks", marks, "--no-preview")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    with SessionReader(path) as reader:
        return SimpleNamespace(
            path=path, episodes=reader.episodes(), metadata=reader.metadata,
            events=[m.payload.data for m in reader.messages([topics.EPISODE])],
            scenes=[m.payload.data for m in reader.messages([topics.WORLD])])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two sessions of one episode each: the operator marks the first y, the second not."""
    d = tmp_path_factory.mktemp("physics")
    return SimpleNamespace(dir=d, marked=_record(d / "marked.mcap", "y"), unmarked=_record(d / "unmarked.mcap", "-"))


def test_the_session_records_every_scene_the_world_ran(recorded):
    recorded = recorded.marked
    assert recorded.metadata["world"] == {"world": "physics", "rate_hz": "500", "end_effector": "leap_hand"}
    assert int(recorded.metadata["world_run"]["steps"]) > 500 * EPISODE_S * 0.9  # stepped at 500 Hz throughout
    reasons = [s["reason"] for s in recorded.scenes]
    # the start, the actuators placing the robot at their homes (the scene running then, begun again), and the
    # operator's episode
    operator = [r for r in reasons if r != "robot placed"]
    assert operator[0] == "start" and operator[1].startswith("operator episode 0 (seed 0): pick_place"), reasons
    for scene in recorded.scenes:
        record = scene["layout"]
        assert record["task"] == "pick_place" and isinstance(record["seed"], int)
        layout = layout_from_record(record)  # restores the scene: its objects at the recorded starting poses
        poses = {n: o["position"] for n, o in record["objects"].items()}
        assert {o.name: list(o.position) for o in layout.objects} == poses
    # the operator's scenes stand where its scripts reach: each cup within the spot's jitter of its place
    cup = SPOTS["pick_place"]["cup"]
    for scene in recorded.scenes[1:]:
        anchor, position = scene["layout"]["anchor"], scene["layout"]["objects"]["cup"]["position"]
        assert abs(position[0] - anchor[0] - cup.x) <= cup.jitter + 1e-9
        assert abs(position[1] - anchor[1] - cup.y) <= cup.jitter + 1e-9


def test_each_episode_is_marked_by_the_world_and_the_operators_mark_wins(recorded):
    for session in (recorded.marked, recorded.unmarked):
        judged = [e for e in session.events if e.get("source") == "physics"]
        assert [(e["episode"], e["outcome"]) for e in judged] == [(0, "failure")] and judged[0]["reason"]
        assert session.episodes[0].judged_reason == judged[0]["reason"]
    first, second = recorded.marked.episodes[0], recorded.unmarked.episodes[0]
    assert (first.marked, first.judged, first.outcome) == ("success", "failure", "success")  # y wins, both kept
    assert (second.marked, second.judged, second.outcome) == (None, "failure", "failure")  # the world's mark alone


def test_export_only_selects_by_the_combined_mark(recorded):
    root = recorded.dir / "success"
    ran = teleprev("export", recorded.marked.path, recorded.unmarked.path, "--repo-id", "t/physics", "--root", root,
                   "--only", "success")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    assert "selected: recorded 2; --only success kept 1" in ran.stdout
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    meta = LeRobotDataset("t/physics", root=root, video_backend="pyav").meta.episodes
    kept = [(meta["source_session"][i], meta["source_episode"][i], meta["outcome"][i]) for i in range(len(meta))]
    assert kept == [("marked.mcap", 0, "success")]


def test_the_preview_shows_the_outcome_when_an_episode_ends(tmp_path):
    plan = EpisodeTimes(2, 1.5, 1.5, engage_after_s=0.2, marks="--")
    rec = LiveSession(RecordOptions(out=tmp_path / "shown.mcap", rig=PHYSICS_RIG, episode_plan=plan))
    screen = io.StringIO()
    console = Console(file=screen, width=220, height=40, force_terminal=True, color_system=None)
    rec.start()
    try:
        assert rec.wait_connected(20.0) == []
        run_timed(rec, plan, console, cues=Cues(io.StringIO(), None))
    finally:
        rec.stop()
    with SessionReader(tmp_path / "shown.mcap") as reader:
        first = reader.episodes()[0]
    assert first.judged == "failure"
    assert f"episode 1 (pick_place): FAILURE, by the physics world: {first.judged_reason}" in screen.getvalue()
