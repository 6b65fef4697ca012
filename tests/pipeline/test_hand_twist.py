"""A finger twisting about its own bone (IMU gloves report it) is not read as abduction."""

import numpy as np

from teleprev.human.smplx import angles_from_hand_pose, hand_pose_from_angles
from tests.helpers.pipeline_inputs import PROXIMAL, twisted


def test_twisting_each_proximal_bone_moves_no_abduction(rng):
    for _ in range(200):
        flexion = rng.uniform(-0.2, 1.6, 15)
        abduction = rng.uniform(-0.35, 0.35, 15)
        pose = hand_pose_from_angles(flexion, abduction)
        for twist in (0.8, -0.8):
            f, a = angles_from_hand_pose(twisted(pose, PROXIMAL, twist))
            assert np.max(np.abs(a - abduction)) <= 0.05
            assert np.max(np.abs(f - flexion)) <= 0.05


def test_flexion_past_ninety_degrees_survives_a_twist():
    flexion, abduction = np.full(15, 2.0), np.full(15, 0.2)
    f, a = angles_from_hand_pose(twisted(hand_pose_from_angles(flexion, abduction), range(15), 0.5))
    assert np.allclose(f, flexion, atol=1e-9) and np.allclose(a, abduction, atol=1e-9)


def test_twist_free_poses_read_back_exactly_as_before(rng):
    flexion = rng.uniform(-0.3, 2.0, (500, 15))
    abduction = rng.uniform(-0.5, 0.5, (500, 15))
    f, a = angles_from_hand_pose(hand_pose_from_angles(flexion, abduction))
    assert np.allclose(f, flexion, atol=1e-12) and np.allclose(a, abduction, atol=1e-12)
