"""Pipeline.joint_step: a policy's joint targets become targets as the operator's do: the arm inside its
joint limits, the hand through the Corrector (never in self-collision), unusable actions give none."""

import numpy as np
import pytest

from teleprev import topics
from teleprev.assembly import build_pipeline
from teleprev.messages import JointSample, Logged
from teleprev.pipeline.driver import InputTopics, PipelineDriver
from teleprev.pipeline.step import PipelineState, StepInputs
from teleprev.rig import load_rig
from tests.helpers.sessions import RIGS

T0 = 10**12


@pytest.fixture(scope="module")
def pipelines():
    return {name: build_pipeline(load_rig(RIGS / rig))
            for name, rig in (("leap", "sim.toml"), ("gripper", "sim_gripper.toml"), ("vacuum", "sim_vacuum.toml"))}


def _action(p, q, t_ns=T0, names=None):
    return StepInputs(t_ns, action=JointSample(t_ns, names or p.action_names, np.asarray(q, dtype=float)))


def test_the_arm_is_clipped_into_its_joint_limits_and_flagged(pipelines):
    p = pipelines["leap"]
    n = len(p.arm_names)
    ask = np.concatenate([p.arm_guard.upper + 1.0, np.zeros(len(p.effector_names))])
    ask[0] = p.arm_guard.lower[0] - 2.0
    r = p.joint_step(PipelineState(), _action(p, ask))
    assert np.all(r.arm_target >= p.arm_guard.lower) and np.all(r.arm_target <= p.arm_guard.upper)
    assert r.arm_target[0] == p.arm_guard.lower[0] and np.array_equal(r.arm_target[1:], p.arm_guard.upper[1:n])
    assert "arm_clipped" in r.report["flags"]
    assert np.array_equal(r.update.arm, r.arm_target) and r.update.arm_ns == T0
    inside = np.concatenate([0.5 * (p.arm_guard.lower + p.arm_guard.upper), np.zeros(len(p.effector_names))])
    r = p.joint_step(PipelineState(), _action(p, inside))
    assert "arm_clipped" not in r.report["flags"] and np.array_equal(r.arm_target, inside[:n])


def test_a_colliding_hand_request_is_corrected_collision_free(pipelines, hand, rng):
    p = pipelines["leap"]
    checker = p.effector.corrector.checker
    colliding = next(q for q in hand.sample_uniform(2000, rng) if checker.collides(q))
    arm = 0.5 * (p.arm_guard.lower + p.arm_guard.upper)
    r = p.joint_step(PipelineState(), _action(p, np.concatenate([arm, colliding])))
    assert r.report["corrector"] in ("ccn", "fallback")
    assert not checker.collides(r.corrected) and np.array_equal(r.update.hand, r.corrected)
    assert np.array_equal(r.retargeted, hand.clip(colliding))  # recorded: the request within its limits
    assert r.state.effector_q is r.corrected and np.array_equal(r.state.arm_q, arm)


def test_hand_requests_beyond_the_limits_are_clipped_for_gripper_and_switched_for_vacuum(pipelines):
    g = pipelines["gripper"]
    r = g.joint_step(PipelineState(), _action(g, np.concatenate([np.zeros(len(g.arm_names)), [5.0]])))
    assert r.corrected[0] == g.effector.guard.upper[0]
    v = pipelines["vacuum"]
    r = v.joint_step(PipelineState(), _action(v, np.concatenate([np.zeros(len(v.arm_names)), [0.7]])))
    assert r.corrected.tolist() == [1.0]


def test_stale_partial_or_non_finite_actions_give_no_target(pipelines):
    p = pipelines["leap"]
    q = np.zeros(len(p.action_names))
    stale = StepInputs(T0 + int(p.cfg.stale_ms * 1e6) + 1, action=JointSample(T0, p.action_names, q))
    bad = q.copy()
    bad[3] = np.nan
    for inputs, flag in ((stale, "policy_stale"), (StepInputs(T0), "no_policy"), (_action(p, bad), "policy_invalid"),
                         (_action(p, q[:-1], names=p.action_names[:-1]), "policy_invalid")):
        r = p.joint_step(PipelineState(), inputs)
        assert flag in r.report["flags"]
        assert r.arm_target is None and r.corrected is None and r.update.arm is None and r.update.hand is None


def test_actions_are_taken_by_name_in_any_order(pipelines):
    p = pipelines["leap"]
    q = np.linspace(-0.2, 0.2, len(p.action_names))
    order = np.random.default_rng(3).permutation(len(q))
    shuffled = _action(p, q[order], names=tuple(p.action_names[i] for i in order))
    assert np.array_equal(p.joint_step(PipelineState(), shuffled).arm_target,
                          p.joint_step(PipelineState(), _action(p, q)).arm_target)


def test_with_an_action_topic_the_driver_steps_on_actions_only(pipelines):
    p = pipelines["leap"]
    inputs = InputTopics("/glove/g/hand", "/suit/s/wrist", "/arm/a/state", "/hand/h/state", topics.POLICY_ACTION)
    driver = PipelineDriver(p, inputs)
    glove = JointSample(T0, ("x",), np.zeros(1))
    assert driver.feed(Logged(inputs.hand, T0, glove)).result is None  # the glove steps nothing
    q = np.zeros(len(p.action_names))
    out = driver.feed(Logged(topics.POLICY_ACTION, T0 + 1, JointSample(T0, p.action_names, q)))
    assert out.result is not None and [t for t, _ in out.logged][:3] == [
        topics.RETARGETED,
        topics.CORRECTED,
        topics.ARM_TARGET,
    ]
    assert len(driver.take_updates()) == 1
