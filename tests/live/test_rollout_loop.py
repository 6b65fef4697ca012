"""The whole loop on the sim rig: a recorded demo -> `teleprev export` -> `lerobot-train` (a tiny ACT) ->
`teleprev rollout` (2 episodes, each previewed, then executed) -> `teleprev audit` passes, `teleprev eval`
re-runs it from its recorded actions bit for bit, and `teleprev export` makes a dataset of it. On the physics
rig the rollout marks its episode by the world and prints each task's success rate."""

from __future__ import annotations

import numpy as np

from teleprev import topics
from teleprev.evaluation.reproduce import rerun_session
from teleprev.session.reader import SessionReader
from tests.helpers.cli import ROOT, teleprev
from tests.helpers.policies import train_tiny_act
from tests.helpers.sessions import colliding_hand_rig

EPISODES, EPISODE_S, ENGAGE_S = 2, 2.5, 0.6


def _read(path):
    with SessionReader(path) as reader:
        return (reader.metadata, [(m.log_time_ns, m.payload) for m in reader.messages([topics.POLICY_ACTION])],
                [(m.log_time_ns, m.payload.data) for m in reader.messages([topics.MODE])],
                [m.payload.stamp_ns for m in reader.messages([topics.COMMAND_ARM])], reader.episodes())


def test_record_export_train_rollout_audit_eval_export(tmp_path, sim_session, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")  # nothing is downloaded: no pretrained backbone, no Hub
    demo = tmp_path / "demo"
    ran = teleprev("export", sim_session, "--repo-id", "lab/demo", "--root", demo)
    assert ran.returncode == 0, ran.stderr
    policy = train_tiny_act(demo, "lab/demo", tmp_path / "train")

    # on the physics rig every episode is marked by the world, and the rollout says each task's success rate
    # (lerobot-eval's pc_success) from the marks it recorded
    physics = tmp_path / "physics.mcap"
    ran = teleprev("rollout", "--policy", policy, "--config", ROOT / "rigs" / "sim_physics.toml", "--task",
                   "pick_place", "--episodes", 1, "--episode-time", EPISODE_S, "--engage-after", ENGAGE_S,
                   "--out", physics)
    # (exit 1 where the policy never acted in time to engage: the episode is recorded and judged all the same)
    assert ran.returncode in (0, 1), ran.stdout + ran.stderr
    with SessionReader(physics) as reader:
        (judged,) = reader.episodes()
    assert judged.judged in ("success", "failure") and judged.judged_reason
    won = int(judged.judged == "success")
    assert f"success pick_place: {won} of 1 episodes (pc_success {100.0 * won:.1f})" in ran.stdout, ran.stdout

    session = tmp_path / "rollout.mcap"
    ran = teleprev("rollout", "--policy", policy, "--episodes", EPISODES, "--episode-time", EPISODE_S,
                   "--engage-after", ENGAGE_S, "--out", session)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "inferences" in ran.stdout and "actions handed on at 30 fps" in ran.stdout

    # a rollout that never engages (its hand starts in self-collision: every engage refused) exits 1, saying why
    refused = teleprev("rollout", "--policy", policy, "--config", colliding_hand_rig(tmp_path), "--episodes", 1,
                       "--episode-time", 1.5, "--engage-after", 0.3, "--out", tmp_path / "refused.mcap")
    assert refused.returncode == 1, refused.stdout + refused.stderr
    said = " ".join(refused.stderr.split())
    assert "never engaged (--engage-after 0.3 s)" in said and "self-collision" in said, said

    meta, actions, modes, commands, episodes = _read(session)
    assert meta["policy"]["type"] == "act" and meta["policy"]["fps"] == "30"
    # each episode engaged for up to 1.9 s (once the policy's first plan is previewed): commands at 120 Hz,
    # whatever the policy's rate (291 and 415 in two runs on a busy 2-core machine)
    assert len(episodes) == EPISODES and len(actions) > 30 and len(commands) > 150
    names = actions[0][1].names
    assert names[:6] == tuple(f"arm.joint{k}" for k in range(1, 7)) and names[6:] == tuple(
        f"hand.{k}" for k in range(16)
    )
    engages = [t for t, d in modes if d["mode"] == "execute"]
    assert len(engages) == EPISODES
    for ep, engaged in zip(episodes, engages):
        assert ep.start_ns < engaged < ep.stop_ns
        # previewed first: the policy's targets came for a while before the robot was engaged
        assert any(ep.start_ns < t < engaged for t, _ in actions)
    assert min(commands) > engages[0]  # in preview the robot received no motion command

    ran = teleprev("audit", session)
    assert ran.returncode == 0 and "audit passed" in ran.stdout, ran.stdout
    ran = teleprev("eval", session, "--out", tmp_path / "eval.json")
    assert ran.returncode == 0 and "bit for bit" in ran.stdout, ran.stdout
    rerun = rerun_session(session)  # the re-run stepped on the recorded actions, one step each
    assert rerun.t_ns.tolist() == [t for t, _ in actions]
    arm_targets = rerun.rerun[topics.ARM_TARGET]
    assert np.array_equal(arm_targets, rerun.recorded[topics.ARM_TARGET])

    data = tmp_path / "rollouts"
    ran = teleprev("export", session, "--repo-id", "lab/rollouts", "--root", data)
    assert ran.returncode == 0, ran.stderr
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    back = LeRobotDataset("lab/rollouts", root=data, video_backend="pyav")
    assert back.meta.total_episodes == EPISODES and back.meta.features["action"]["names"] == list(names)
