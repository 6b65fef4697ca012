"""One operator, two sides: each side's own pipeline from the bimanual rig, the left glove mirrored into the
right hand's terms, one mode for both, and a fault on one side braking both."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from teleprev.bimanual import build_bimanual_driver
from teleprev.human import smplx
from teleprev.human.mirror import mirror_hand_pose, mirror_wrist
from teleprev.messages import JointSample, Logged, PoseSample
from teleprev.pipeline.bimanual import side_topic
from teleprev.pipeline.planner import ModeUpdate
from teleprev.rig import load_rig
from teleprev.transforms import matrix_to_quat, rpy_to_matrix

ROOT = Path(__file__).resolve().parents[2]
HOME = np.array([0.0, -0.27, -0.11, 0.0, -0.85, -1.571])


@pytest.fixture(scope="module")
def rig():
    return load_rig(ROOT / "rigs" / "sim_bimanual.toml")


def _feed_side(driver, rig, side, t_ns, pose, wrist_p, wrist_r, arm=True):
    d = rig.sides[side].devices
    out = {}
    msgs = [Logged(f"/suit/{d['suit']}/wrist", t_ns, PoseSample(t_ns, "suit", wrist_p, matrix_to_quat(wrist_r))),
            Logged(f"/hand/{d['hand']}/state", t_ns + 1, JointSample(t_ns, tuple(str(i) for i in range(16)),
                                                                    np.zeros(16)))]
    if arm:
        arm_names = tuple(f"joint{i}" for i in range(1, 7))
        msgs.append(Logged(f"/arm/{d['arm']}/state", t_ns + 2, JointSample(t_ns, arm_names, HOME.copy())))
    msgs.append(Logged(f"/glove/{d['glove']}/hand", t_ns + 3, JointSample(t_ns, smplx.HAND_POSE_NAMES, pose)))
    for m in msgs:
        for s, o in driver.feed(m).items():
            if o.result is not None:
                out[s] = o
    return out


def _operator(k: int):
    """The operator's right hand and wrist at step k: fingers closing, wrist moving forward."""
    flexion = np.full(15, 0.05 * k)
    abduction = np.linspace(-0.1, 0.1, 15)
    pose = smplx.hand_pose_from_angles(flexion, abduction).reshape(45)
    return pose, np.array([0.3 + 0.002 * k, -0.2, 1.1]), rpy_to_matrix(0.1, 0.2, 0.05 * k)


def test_mirror_is_its_own_inverse():
    pose, p, r = _operator(7)
    np.testing.assert_array_equal(mirror_hand_pose(mirror_hand_pose(pose)), pose)
    p2, r2 = mirror_wrist(*mirror_wrist(p, r))
    np.testing.assert_allclose(p2, p)
    np.testing.assert_allclose(r2, r)
    shuffled = tuple(reversed(smplx.HAND_POSE_NAMES))
    np.testing.assert_array_equal(mirror_hand_pose(pose[::-1], shuffled), mirror_hand_pose(pose)[::-1])


def test_left_glove_mirrored_gives_the_right_hands_targets(rig):
    """The left hand mirrors the right one: the operator's mirrored left hand gives the left robot hand
    exactly the joint targets the right hand gets (retargeted and corrected), on each side's own pipeline."""
    driver = build_bimanual_driver(rig)
    left, right = driver.drivers["left"].pipeline, driver.drivers["right"].pipeline
    assert left is not right and left.effector.corrector is not right.effector.corrector
    assert left.effector.corrector.model.name == "leap_hand_left"
    compared = 0
    for k in range(0, 30, 3):
        pose, p, r = _operator(k)
        t = 1_000_000_000 + k * 10_000_000
        got_r = _feed_side(driver, rig, "right", t, pose, p, r)["right"]
        got_l = _feed_side(driver, rig, "left", t + 5, mirror_hand_pose(pose), *mirror_wrist(p, r))["left"]
        np.testing.assert_array_equal(got_l.result.retargeted, got_r.result.retargeted)
        np.testing.assert_array_equal(got_l.result.corrected, got_r.result.corrected)
        topics = {topic for topic, _ in got_l.logged}
        assert "/pipeline/left/corrected" in topics and "/pipeline/left/arm_target" in topics
        compared += 1
    assert compared == 10
    flexed = got_r.result.retargeted
    assert np.abs(flexed).max() > 0.3  # the fingers did close: the comparison is not of open hands


def test_execute_switches_both_sides_or_neither(rig):
    driver = build_bimanual_driver(rig)
    pose, p, r = _operator(0)
    _feed_side(driver, rig, "right", 1_000_000_000, pose, p, r)
    _feed_side(driver, rig, "left", 1_000_000_010, mirror_hand_pose(pose), *mirror_wrist(p, r), arm=False)
    refused = driver.request_mode("execute", 1_000_000_100)
    assert refused.startswith("left: ")
    assert driver.mode == "preview" and driver.drivers["right"].state.mode == "preview"
    modes = {side: [u for u in ups if isinstance(u, ModeUpdate)] for side, ups in driver.take_updates().items()}
    assert modes == {"left": [], "right": []}  # no switch reached either planner
    _feed_side(driver, rig, "left", 1_000_000_200, mirror_hand_pose(pose), *mirror_wrist(p, r))
    assert driver.request_mode("execute", 1_000_000_300) == ""
    assert driver.mode == "execute"
    updates = driver.take_updates()
    assert [u.mode for u in updates["left"] if isinstance(u, ModeUpdate)] == ["execute"]
    assert [u.mode for u in updates["right"] if isinstance(u, ModeUpdate)] == ["execute"]


def test_a_fault_on_one_side_brakes_both(rig):
    driver = build_bimanual_driver(rig)
    pose, p, r = _operator(0)
    for side in ("right", "left"):
        mp, mw = (pose, (p, r)) if side == "right" else (mirror_hand_pose(pose), mirror_wrist(p, r))
        _feed_side(driver, rig, side, 1_000_000_000, mp, *mw)
    assert driver.request_mode("execute", 1_000_000_100) == ""
    driver.take_updates()
    driver.fault("left", "arm_left: controller error 22", 1_000_000_200)
    assert driver.mode == "preview" and driver.faults == {"left": "arm_left: controller error 22"}
    updates = driver.take_updates()
    assert [u.mode for u in updates["left"]] == ["halt"]  # the faulted side: nothing more is sent
    assert [u.mode for u in updates["right"]] == ["preview"]  # the other: brakes to rest, holds its grip
    # a step after the fault stays in preview on both sides: nothing moves until the operator engages
    _feed_side(driver, rig, "right", 1_000_000_300, pose, p, r)
    _feed_side(driver, rig, "left", 1_000_000_300, mirror_hand_pose(pose), *mirror_wrist(p, r))
    assert driver.mode == "preview"
    assert driver.request_mode("execute", 1_000_000_400) == "" and driver.faults == {}


def test_side_topics():
    assert side_topic("/pipeline/retargeted", "left") == "/pipeline/left/retargeted"
    assert side_topic("/command/arm", "right") == "/command/right/arm"
