"""`teleprev rollout --config rigs/sim_bimanual.toml`: a tiny ACT trained on the bimanual export drives both
sides, its 44-value action split by name into each side's (left_arm.joint1 .. left_hand.15 to the left side's
pipeline on /policy/left/action, the rest to the right's); each side's commands within its own limits."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from teleprev.session.reader import SessionReader
from tests.bimanual.test_record_export import expected_names
from tests.helpers.cli import teleprev

RIG = Path(__file__).resolve().parents[2] / "rigs" / "sim_bimanual.toml"
SIDE_NAMES = tuple(f"arm.joint{k}" for k in range(1, 7)) + tuple(f"hand.{k}" for k in range(16))


def test_the_action_is_split_by_name_into_the_sides(policy, tmp_path):
    """What the rollout hands the session loop for one action of the policy (before anything starts)."""
    from teleprev.live.rollout.lerobot_policy import LeRobotPolicy  # noqa: F401  (the command's import path)
    from teleprev.live.rollout.rollout import Rollout, RolloutOptions, check_rollout

    options = RolloutOptions(policy=policy, out=tmp_path / "r.mcap", rig=RIG, episode_time_s=2.0,
                             engage_after_s=0.5)
    plan = check_rollout(options)
    assert plan.action_names == tuple(expected_names())
    run = Rollout(options, plan, policy=None)
    try:
        run._deliver(np.arange(44.0))
        handed = [run.recording.loop.inbox.queue.get_nowait()[1] for _ in range(2)]
    finally:
        run.recording.stop()
    assert [s.topic for s in handed] == ["/policy/left/action", "/policy/right/action"]
    for k, sample in enumerate(handed):
        assert sample.payload.names == SIDE_NAMES
        np.testing.assert_array_equal(sample.payload.positions, np.arange(22.0) + 22 * k)


def test_a_bimanual_policy_rolls_out_on_the_sim_bimanual_rig(policy, tmp_path):
    out = tmp_path / "rollout.mcap"
    ran = teleprev("rollout", "--policy", policy, "--config", RIG, "--episodes", 1, "--episode-time", 4,
                   "--engage-after", 0.5, "--out", out)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "inferences" in ran.stdout
    with SessionReader(out) as reader:
        assert reader.metadata["policy"]["action_names"].split(",") == expected_names()
        actions = {side: [m.payload for m in reader.messages([f"/policy/{side}/action"])] for side in ("left", "right")}
        assert len(actions["left"]) == len(actions["right"]) >= 1
        assert [a.stamp_ns for a in actions["left"]] == [a.stamp_ns for a in actions["right"]]
        assert all(a.names == SIDE_NAMES for side in actions.values() for a in side)
        engaged = [m for m in reader.messages(["/events/mode"]) if m.payload.data["mode"] == "execute"]
        commands = {side: sum(1 for _ in reader.messages([f"/command/{side}/arm"])) for side in ("left", "right")}
    assert engaged and min(commands.values()) > 50, commands
    audit = teleprev("audit", out, "--json", tmp_path / "audit.json")
    assert audit.returncode == 0, audit.stdout
    (report,) = json.loads((tmp_path / "audit.json").read_text())
    assert [s["topic"] for s in report["streams"]] == [f"/command/{s}/{k}" for s in ("left", "right")
                                                       for k in ("arm", "hand")]
