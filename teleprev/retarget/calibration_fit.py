"""From an operator's open hand, fist and neutral wrist to a Calibration.

Each LEAP joint driven by a flexion gets the scale and offset that put the operator's open hand at 0
and their fist at the joint's closed target below; joints driven by an abduction only get their open
hand offset (the spread at rest becomes 0). The neutral wrist (fingers pointing where the operator
calls forward) gives the yaw between the suit's frame and the robot's.
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from teleprev.human.smplx import JOINT_INDEX, angles_from_hand_pose
from teleprev.retarget.calibration import Calibration, CalibrationSection, JointCalibration
from teleprev.retarget.hand import DEFAULT_LEAP_MAP

# Where a fist should put each flexion joint (rad): a firm but collision-aware closure.
FIST_TARGET = {
    "1": 1.5, "2": 1.6, "3": 1.1, "5": 1.5, "6": 1.6, "7": 1.1, "9": 1.5, "10": 1.6, "11": 1.1,
    "13": 0.9, "14": 0.8, "15": 0.8,
}
MIN_RANGE = 0.2  # rad: a joint the operator moved less than this between open and fist keeps scale 1


def mean_angles(hand_poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Average flexion and abduction (15,) over hand poses (N, 15, 3)."""
    flexion, abduction = angles_from_hand_pose(np.asarray(hand_poses, dtype=float))
    return flexion.mean(axis=0), abduction.mean(axis=0)


def calibrate(
    open_poses: np.ndarray, fist_poses: np.ndarray, neutral_wrist: np.ndarray, operator: str = ""
) -> Calibration:
    """open_poses, fist_poses: (N, 15, 3) hand poses held still; neutral_wrist: (N, 3, 3) wrist rotations."""
    open_f, open_a = mean_angles(open_poses)
    fist_f, _ = mean_angles(fist_poses)
    joints = {}
    for name, m in DEFAULT_LEAP_MAP.items():
        i = JOINT_INDEX[m.source]
        if m.angle == "abduction":
            joints[name] = JointCalibration(scale=1.0, offset=float(-m.sign * open_a[i]))
            continue
        span = fist_f[i] - open_f[i]
        scale = FIST_TARGET[name] / (m.sign * span) if abs(span) >= MIN_RANGE else 1.0
        joints[name] = JointCalibration(scale=float(scale), offset=float(-m.sign * scale * open_f[i]))
    # Fingers point along the hand frame's -x; their heading on the floor is the operator's forward.
    forward = np.mean(np.asarray(neutral_wrist, dtype=float) @ np.array([-1.0, 0.0, 0.0]), axis=0)
    yaw = float(np.arctan2(forward[1], forward[0]))
    return Calibration(
        CalibrationSection(suit_yaw=-yaw, created=_dt.datetime.now().isoformat(timespec="seconds"), operator=operator),
        joints,
    )
