"""SMPL-X hand poses to LEAP joints, and the one-finger end effectors."""

import numpy as np
import pytest

from teleprev.human.smplx import JOINT_INDEX, angles_from_hand_pose, hand_pose_from_angles
from teleprev.retarget.end_effector import GripperMap, VacuumMap
from teleprev.retarget.hand import LeapRetargeter


def _pose(**angles):
    """A hand pose from per-joint (flexion, abduction), e.g. index1=(1.0, 0.1)."""
    flexion, abduction = np.zeros(15), np.zeros(15)
    for joint, (f, a) in angles.items():
        flexion[JOINT_INDEX[joint]], abduction[JOINT_INDEX[joint]] = f, a
    return hand_pose_from_angles(flexion, abduction)


@pytest.fixture(scope="module")
def retarget(hand):
    return LeapRetargeter(hand)


def test_angles_round_trip_through_axis_angle(rng):
    flexion, abduction = rng.uniform(-0.5, 2.0, (50, 15)), rng.uniform(-0.6, 0.6, (50, 15))
    f, a = angles_from_hand_pose(hand_pose_from_angles(flexion, abduction))
    assert np.allclose(f, flexion, atol=1e-12) and np.allclose(a, abduction, atol=1e-12)


def test_closed_form_pose_equals_the_rotations_it_stands_for(rng):
    from teleprev.human.smplx import JOINT_FRAMES
    from teleprev.transforms import axis_angle_to_matrix, rpy_to_matrix

    flexion, abduction = rng.uniform(-3.0, 3.0, (20, 15)), rng.uniform(-3.0, 3.0, (20, 15))
    for abduction_first in (False, True):  # flexion first (format 5 on), abduction first (formats 1 to 4)
        pose = hand_pose_from_angles(flexion, abduction, abduction_first=abduction_first)
        for n in range(20):
            for j in range(15):
                b = JOINT_FRAMES[j]
                flex, abd = rpy_to_matrix(0.0, 0.0, flexion[n, j]), rpy_to_matrix(0.0, abduction[n, j], 0.0)
                expected = b @ (abd @ flex if abduction_first else flex @ abd) @ b.T
                assert np.allclose(axis_angle_to_matrix(pose[n, j]), expected, atol=1e-12)
                assert np.linalg.norm(pose[n, j]) <= np.pi + 1e-12
        one = hand_pose_from_angles(flexion[0], abduction[0], abduction_first=abduction_first)
        assert np.array_equal(one, pose[0])


def test_open_hand_is_the_open_leap_hand(retarget):
    assert np.allclose(retarget(_pose()), 0.0, atol=1e-12)


def test_fist_curls_every_finger_joint(retarget, hand):
    fist = {f"{f}{i}": (1.4, 0.0) for f in ("index", "middle", "ring", "pinky") for i in (1, 2, 3)}
    q = retarget(_pose(**fist, thumb1=(0.6, 0.2), thumb2=(0.8, 0.0), thumb3=(0.5, 0.0)))
    d = hand.as_dict(q)
    for mcp, pip, dip in (("1", "2", "3"), ("5", "6", "7"), ("9", "10", "11")):
        assert d[mcp] == pytest.approx(1.4) and d[pip] == pytest.approx(1.4) and d[dip] == pytest.approx(1.4)
    assert (d["12"], d["13"], d["14"], d["15"]) == pytest.approx((-0.2, 0.6, 0.8, 0.5))


def test_pinch_moves_only_thumb_and_index(retarget, hand):
    q = hand.as_dict(
        retarget(_pose(index1=(0.7, 0.05), index2=(0.9, 0), index3=(0.4, 0), thumb1=(0.5, 0.3), thumb2=(0.6, 0)))
    )
    assert (q["0"], q["1"], q["2"], q["3"]) == pytest.approx((-0.05, 0.7, 0.9, 0.4))
    assert all(q[str(j)] == pytest.approx(0.0, abs=1e-12) for j in range(4, 12))


def test_beyond_the_limits_is_clamped(retarget, hand):
    q = hand.as_dict(retarget(_pose(index2=(2.5, 0.0), middle1=(0.2, -1.2))))
    assert q["2"] == pytest.approx(1.885) and q["4"] == pytest.approx(1.047)


def test_gripper_opening_follows_flexion():
    g = GripperMap(0.085, 1.2)
    assert g(0.0) == pytest.approx(0.085) and g(1.2) == 0.0 and g(2.0) == 0.0 and g(-0.3) == pytest.approx(0.085)
    assert g(0.6) == pytest.approx(0.0425)


def test_vacuum_has_hysteresis_and_does_not_chatter():
    v = VacuumMap(on_flexion=0.9, off_flexion=0.6)
    state, switches = False, 0
    for flexion in [0.0, 0.5, 0.95, 0.85, 0.7, 0.65, 0.88, 0.61, 0.55, 0.8, 0.89, 0.92]:
        new = v(flexion, state)
        switches += new != state
        state = new
    assert switches == 3  # on at 0.95, off at 0.55, on at 0.92; the wobbles in between change nothing
    assert v(0.75, True) is True and v(0.75, False) is False
    with pytest.raises(ValueError):
        VacuumMap(on_flexion=0.5, off_flexion=0.6)
