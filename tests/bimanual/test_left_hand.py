"""The left LEAP Hand: generated from the right one by our script, its mirror image at every joint angle,
colliding exactly where the right one does, and corrected by the right hand's networks unchanged."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import load_robot

ROOT = Path(__file__).resolve().parents[2]
M = np.diag([1.0, -1.0, 1.0])


@pytest.fixture(scope="module")
def hands():
    return load_robot("leap_hand_right"), load_robot("leap_hand_left")


def _mirrored(pose: np.ndarray) -> np.ndarray:
    out = pose.copy()
    out[:3, :3] = M @ pose[:3, :3] @ M
    out[:3, 3] = M @ pose[:3, 3]
    return out


def test_urdf_files_are_what_the_script_writes():
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "mirror_leap_hand.py"), "--check"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_fk_of_left_is_mirror_of_right(hands, rng):
    right, left = hands
    assert left.joint_names == right.joint_names and left.link_names == right.link_names
    np.testing.assert_array_equal(left.lower, right.lower)
    np.testing.assert_array_equal(left.upper, right.upper)
    for q in right.sample_uniform(50, rng):
        fr, fl = right.fk(q), left.fk(q)
        for link in right.link_names:
            np.testing.assert_allclose(fl.matrix(link), _mirrored(fr.matrix(link)), atol=1e-9, err_msg=link)
    # a mirror, not a copy: the palm sits on the other side of the flange
    q0 = right.neutral()
    assert right.fk(q0).position("palm_lower")[1] == pytest.approx(-left.fk(q0).position("palm_lower")[1])
    assert abs(right.fk(q0).position("palm_lower")[1]) > 0.01


def test_arm_with_left_hand_mirrors_the_hand_on_the_same_flange(rng):
    right, left = load_robot("xarm6_leap_hand"), load_robot("xarm6_leap_hand_left")
    for q in right.sample_uniform(10, rng):
        fr, fl = right.fk(q), left.fk(q)
        np.testing.assert_allclose(fl.matrix("link_eef"), fr.matrix("link_eef"), atol=1e-12)  # the arm is the arm
        base_r, base_l = fr.matrix("base"), fl.matrix("base")
        for link in ("palm_lower", "fingertip", "thumb_fingertip"):
            in_base_r = np.linalg.inv(base_r) @ fr.matrix(link)
            in_base_l = np.linalg.inv(base_l) @ fl.matrix(link)
            np.testing.assert_allclose(in_base_l, _mirrored(in_base_r), atol=1e-9, err_msg=link)


def test_self_collision_is_the_same_at_every_angle(hands, rng):
    right, left = hands
    cr, cl = SelfCollisionChecker(right), SelfCollisionChecker(left)
    q = right.sample_uniform(3000, rng)
    a = np.array([cr.collides(x) for x in q])
    assert 0 < a.sum() < len(a)  # both answers occur
    np.testing.assert_array_equal(a, [cl.collides(x) for x in q])


def test_left_corrector_answers_as_the_right_one(hands, rng):
    from teleprev.noncollision.corrector import Corrector
    from teleprev.noncollision.mirrored import load_corrector

    right, left = hands
    cr = load_corrector(Corrector, None, right)
    cl = load_corrector(Corrector, None, left)
    assert cl.model.name == "leap_hand_left" and cl.checker.model.name == "leap_hand_left"
    actions = set()
    for q in right.sample_uniform(40, rng):
        a, b = cr.correct(q), cl.correct(q)
        np.testing.assert_array_equal(a.q, b.q)
        assert a.action == b.action
        actions.add(a.action)
        assert not cl.checker.collides(b.q)
    assert "ccn" in actions or "fallback" in actions  # colliding inputs were among them
