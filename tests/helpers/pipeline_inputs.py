"""Synthetic operator inputs for pipeline tests: a smooth hand and wrist motion, as the sim would send."""

from __future__ import annotations

import numpy as np

from teleprev.human.smplx import HAND_POSE_NAMES, JOINT_FRAMES, hand_pose_from_angles
from teleprev.messages import JointSample, PoseSample
from teleprev.pipeline.step import StepInputs
from teleprev.transforms import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_quat

RATE_HZ = 120.0
ARM_HOME = np.array([0.0, -0.5, -0.6, 0.0, 1.1, 0.0])


def hand_sample(t_ns: int, flexion, abduction=None) -> JointSample:
    abduction = np.zeros(15) if abduction is None else abduction
    return JointSample(
        t_ns, HAND_POSE_NAMES, hand_pose_from_angles(np.asarray(flexion, float), np.asarray(abduction, float)).ravel()
    )


def wrist_sample(t_ns: int, k: int) -> PoseSample:
    position = np.array([0.3 + 0.12 * np.sin(k / 90), 0.08 * np.sin(k / 70), 1.0 + 0.05 * np.sin(k / 50)])
    rotation = axis_angle_to_matrix(np.array([0.0, 0.15 * np.sin(k / 110), 0.25 * np.sin(k / 80)]))
    return PoseSample(t_ns, "suit", position, matrix_to_quat(rotation))


def inputs(k: int, arm_names, effector_names, effector_q, flexion=None) -> StepInputs:
    t = int(k * 1e9 / RATE_HZ)
    flexion = np.full(15, 0.3 + 0.5 * (1 - np.cos(k / 40))) if flexion is None else flexion
    return StepInputs(
        t,
        hand_sample(t, flexion),
        wrist_sample(t, k),
        JointSample(t, tuple(arm_names), ARM_HOME.copy()),
        JointSample(t, tuple(effector_names), np.asarray(effector_q, float)),
    )


PROXIMAL = [0, 3, 6, 9, 12]  # index1, middle1, pinky1, ring1, thumb1


def twisted(pose: np.ndarray, joints, twist: float) -> np.ndarray:
    """The (15, 3) hand pose with each joint's segment turned by `twist` about its own bone (x in its joint
    frame), as an IMU glove reports a finger rolling about itself."""
    out = pose.copy()
    c, s = np.cos(twist), np.sin(twist)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    for j in joints:
        b = JOINT_FRAMES[j]
        out[j] = matrix_to_axis_angle(axis_angle_to_matrix(pose[j]) @ b @ rx @ b.T)
    return out
