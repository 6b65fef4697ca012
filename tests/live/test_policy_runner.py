"""The policy runner: plans queued ahead and handed on one per frame; when actions stop, a real sim session's
commands go on leaving at the sender's rate and brake to rest, as for a silent glove.

The policies here are small scripted ones (the runner is what is tested); tests/live/test_rollout_loop.py
runs a policy trained with lerobot-train."""

from __future__ import annotations

import threading
import time

import numpy as np

from teleprev import topics
from teleprev.export.recipe import load_recipe
from teleprev.live.rollout.lerobot_policy import PolicyCard
from teleprev.live.rollout.policy import PolicyFeatures, PolicyRunner
from teleprev.live.rollout.rollout import Rollout, RolloutOptions, RolloutPlan, _joint_names, _rig_streams
from teleprev.messages import Event
from teleprev.rig import load_rig
from teleprev.session.reader import SessionReader
from tests.helpers.sessions import RIGS
from tests.helpers.wait import wait_until


class CountingPolicy:
    """Each plan: `size` consecutive numbers continuing the last plan's first, after `think_s` of inference."""

    def __init__(self, size: int, think_s: float):
        self.size, self.think_s, self.calls = size, think_s, 0

    def chunk(self, observation, task):
        first = self.calls * 1000
        self.calls += 1
        time.sleep(self.think_s)
        return np.arange(first, first + self.size, dtype=float)[:, None]

    def reset(self):
        pass


def _run(policy, fps: float, done, what: str, timeout_s: float = 10.0):
    """Run a policy until `done(stats, handed)` holds (handed: (monotonic time, first value) of each action)."""
    handed: list[tuple[float, float]] = []
    runner = PolicyRunner(policy, lambda: {}, lambda a: handed.append((time.monotonic(), float(a[0]))), fps).start()
    try:
        wait_until(lambda: done(runner.stats, handed), timeout_s, what=what)
    finally:
        runner.stop()
    return runner.stats, handed


def test_plans_are_queued_ahead_and_handed_on_one_per_frame():
    stats, handed = _run(CountingPolicy(size=10, think_s=0.01), 50.0, lambda st, h: len(h) >= 75 and st.inferences >= 5,
                         "75 actions handed on (1.5 s at 50 fps)")
    values = [v for _, v in handed]
    assert stats.failure == ""
    # none dropped but for an inference that took longer than a frame (a busy machine's)
    assert stats.dropped == sum(min(int(took / 0.02), 9) for took in stats.inference_s), stats
    # the next plan arrives before the queue runs dry: after the first frame, every frame hands one on
    assert stats.starved <= 2, stats
    gaps = np.diff([t for t, _ in handed])
    assert 0.015 < float(np.median(gaps)) < 0.025 and gaps.max() < 0.1
    # within a plan the actions go on in order; a new plan replaces what was left (from its first action on)
    for a, b in zip(values, values[1:]):
        assert b == a + 1 or b % 1000 == 0, (a, b)


def test_actions_for_frames_that_passed_during_inference_are_dropped_but_the_last_kept():
    stats, handed = _run(CountingPolicy(size=6, think_s=0.07), 50.0, lambda st, h: st.inferences >= 8,
                         "8 inferences of 70 ms")
    firsts = [v % 1000 for (_, v), (_, before) in zip(handed[1:], handed) if int(v) // 1000 != int(before) // 1000]
    assert firsts and min(firsts) >= 3  # 70 ms of inference at 50 fps: its first 3 frames had passed
    assert stats.dropped >= 3 * (stats.inferences - 1)
    stats, handed = _run(CountingPolicy(size=3, think_s=0.15), 50.0, lambda st, h: len(h) >= 4,  # slower than its plan
                         "4 actions of a policy slower than its plan")
    assert all(v % 1000 == 2 for _, v in handed)  # each plan's last action still moves the robot


class HoldThenStall:
    """Plans the observed state with the arm's first joint 0.4 rad on, for `active_s` from its first call;
    then it stalls (an inference that does not come back within the session)."""

    def __init__(self, active_s: float):
        self.active_s, self.started, self.seen = active_s, None, []
        self.release = threading.Event()

    def chunk(self, observation, task):
        self.started = self.started or time.monotonic()
        if time.monotonic() - self.started > self.active_s:
            self.release.wait(10.0)
            return np.zeros((1, 22))
        self.seen.append({k: v.shape for k, v in observation.items()})
        state = observation["observation.state"].astype(float)
        state[0] += 0.4
        return np.repeat(state[None], 10, axis=0)

    def reset(self):
        pass


def test_when_actions_stop_the_commands_go_on_and_brake_to_rest(tmp_path):
    rig = load_rig(RIGS / "sim.toml")
    recipe = load_recipe(None)
    streams, _, inputs = _rig_streams(rig)
    features = PolicyFeatures.for_streams(recipe, streams, inputs)
    arm, effector = _joint_names(rig)
    names = tuple(f"arm.{n}" for n in arm) + tuple(f"hand.{n}" for n in effector)
    folder = tmp_path / "policy"
    folder.mkdir()
    (folder / "model.safetensors").write_bytes(b"scripted")
    card = PolicyCard(folder, "scripted", {}, {}, 30)
    out = tmp_path / "stall.mcap"
    options = RolloutOptions(policy=folder, out=out, rig=RIGS / "sim.toml", episodes=1, episode_time_s=3.5,
                             engage_after_s=0.5)
    policy = HoldThenStall(active_s=1.5)
    rollout = Rollout(options, RolloutPlan(card, recipe, rig, features, names, 30.0), policy)
    try:
        result = rollout.run()
    finally:
        policy.release.set()
    assert not result.unconnected and rollout.runner.stats.failure == ""
    assert policy.seen[0] == {"observation.state": (22,), "observation.images.cam_front": (480, 640, 3)}
    with SessionReader(out) as reader:
        actions = [m.payload.stamp_ns for m in reader.messages([topics.POLICY_ACTION])]
        modes = [(m.log_time_ns, m.payload.data["mode"]) for m in reader.messages([topics.MODE])]
        ticks = {m.payload.stamp_ns: m.payload.data for m in reader.messages([topics.COMMAND_TICK])}
        arm_cmds = [m.payload for m in reader.messages([topics.COMMAND_ARM])]
        errors = [m.payload.data for m in reader.messages([topics.DEVICE_EVENT])
                  if isinstance(m.payload, Event) and m.payload.data.get("event") == "error"]
    assert errors == []  # the sim arm (the controller's acceleration and jerk check) never faulted
    engaged = next(t for t, mode in modes if mode == "execute")
    back = next(t for t, mode in modes if mode == "preview" and t > engaged)
    stopped = actions[-1]
    assert engaged < stopped < back - 1.0e9, "the actions stopped while engaged, a second before the episode's end"
    after = [c for c in arm_cmds if stopped + 0.8e9 < c.stamp_ns < back]
    assert len(after) >= 0.8 * 120 * (back - stopped - 0.8e9) / 1e9  # still sent at the sender's rate
    assert max(float(np.abs(c.velocities).max()) for c in after) < 1e-6  # braked to rest, and holding
    assert all("targets_stale" in ticks[c.stamp_ns]["flags"] for c in after)
    moving = [c for c in arm_cmds if engaged < c.stamp_ns < stopped]
    assert max(float(np.abs(c.velocities).max()) for c in moving) > 0.05  # it did move while actions came


class SequencePolicy(CountingPolicy):
    plans_ahead = False  # lerobot's select_action: the next action of the policy's own sequence each call


def test_a_policy_keeping_its_own_sequence_has_every_action_handed_on_in_turn():
    stats, handed = _run(SequencePolicy(size=1, think_s=0.0), 50.0, lambda st, h: len(h) >= 40, "40 actions")
    values = [v // 1000 for _, v in handed]
    assert values == list(range(len(values)))  # none skipped, none superseded
    assert stats.dropped == 0


def test_each_episode_says_once_when_its_first_action_was_handed_on():
    """A rollout's episode executes only once the policy's own targets for it were previewed: the runner
    tells, after each episode's first action (and not for the episode before's plan still queued)."""
    events: list[tuple[str, float]] = []
    runner = PolicyRunner(CountingPolicy(size=5, think_s=0.2), lambda: {},
                          lambda a: events.append(("action", float(a[0]))), fps=50.0,
                          on_acting=lambda: events.append(("acting", 0.0)))
    runner.start()
    try:
        wait_until(lambda: len(events) >= 2, 5.0, what="the first plan handed on")
        runner.new_episode("")
        before = len(events)
        wait_until(lambda: [e for e in events[before:] if e[0] == "acting"], 5.0, what="the new episode acting")
        wait_until(lambda: len(events) >= before + 3, 5.0, what="an action after it")
    finally:
        runner.stop()
    assert [e for e in events[:before] if e[0] == "acting"] == []  # the runner starts as if acting already
    after = events[before:]
    acting = [i for i, e in enumerate(after) if e[0] == "acting"]
    assert len(acting) == 1 and acting[0] >= 1 and after[acting[0] - 1][0] == "action"
    assert after[acting[0] - 1][1] >= 1000  # the new episode's plan, not one inferred before it started
