"""WebXR joints into the SMPL-X hand pose and the suit frame: synthetic hands built from known finger angles."""

import numpy as np
import pytest

from teleprev.human import smplx
from teleprev.transforms import axis_angle_to_matrix
from teleprev_devices.webxr import hands
from tests.helpers.xr_hands import local_rotations, xr_hand


def _rot(axis, angle):
    return axis_angle_to_matrix(np.asarray(axis, dtype=float) * angle)


def synthetic_hand(flexion, abduction, wrist=np.eye(3), twist=None):
    twist = np.array([(twist or {}).get(j, 0.0) for j in smplx.HAND_JOINTS])
    return xr_hand(local_rotations(flexion, abduction, twist), wrist, [0.1, 1.1, -0.3])


@pytest.fixture
def angles(rng):
    return rng.uniform(0.0, 1.2, 15), rng.uniform(-0.3, 0.3, 15)


def test_finger_angles_come_back_from_webxr_joints(angles):
    flexion, abduction = angles
    f, a = smplx.angles_from_hand_pose(hands.hand_pose(synthetic_hand(flexion, abduction)).reshape(15, 3))
    np.testing.assert_allclose(f, flexion, atol=1e-9)
    np.testing.assert_allclose(a, abduction, atol=1e-9)


def test_turning_the_wrist_changes_no_finger_angle(angles):
    flexion, abduction = angles
    turned = _rot([0.3, -0.5, 0.8] / np.linalg.norm([0.3, -0.5, 0.8]), 1.9)
    rest = hands.hand_pose(synthetic_hand(flexion, abduction))
    np.testing.assert_allclose(hands.hand_pose(synthetic_hand(flexion, abduction, wrist=turned)), rest, atol=1e-9)


def test_a_finger_twisting_about_its_bone_never_reads_as_abduction(angles):
    flexion, abduction = angles
    twisted = synthetic_hand(flexion, abduction, twist={"index1": 0.5, "middle2": -0.4, "thumb2": 0.3})
    pose = hands.hand_pose(twisted).reshape(15, 3)
    f, a = smplx.angles_from_hand_pose(pose)
    np.testing.assert_allclose(a, abduction, atol=1e-9)
    np.testing.assert_allclose(f, flexion, atol=1e-9)
    assert (
        np.abs(pose - hands.hand_pose(synthetic_hand(flexion, abduction)).reshape(15, 3)).max() > 0.1
    )  # twist is real


def test_the_wrist_lands_in_the_suit_frame_forward_left_up():
    joints = synthetic_hand(np.zeros(15), np.zeros(15), wrist=hands.A.T)  # fingers along the suit's -x ...
    joints[hands.JOINT_INDEX["wrist"], :3] = [0.1, 1.2, -0.4]  # right 0.1, up 1.2, 0.4 ahead (WebXR: -z)
    position, quat = hands.wrist_in_suit(joints)
    np.testing.assert_allclose(position, [0.4, -0.1, 1.2], atol=1e-6)
    np.testing.assert_allclose(np.abs(quat), [0, 0, 0, 1], atol=1e-6)  # ... so the hand frame is the suit's
