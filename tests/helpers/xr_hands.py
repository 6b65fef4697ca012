"""A right hand as WebXR joints, built from SMPL-X local rotations and a wrist pose: what a headset would
report for a hand in that pose (the inverse of devices/teleprev_devices/webxr/hands.py, written the other
way round: bones chained from the wrist out). Tests build hands from known angles with it, and the browser
tests turn a recorded glove and suit into the hand motion IWER plays."""

from __future__ import annotations

import numpy as np

from teleprev.human import smplx
from teleprev.transforms import axis_angle_to_matrix, matrix_to_quat, quat_to_matrix
from teleprev_devices.webxr import hands

B = smplx.JOINT_FRAMES
# Where each chain's first joint sits in the hand frame (SMPL-X axes: fingers -x, back +y, thumb +z), and
# its bones' lengths, metres: an adult hand's proportions.
_BASE = {"index": (-0.010, 0.0, 0.020), "middle": (-0.010, 0.0, 0.005), "ring": (-0.010, 0.0, -0.010),
         "pinky": (-0.010, 0.0, -0.022), "thumb": (-0.020, -0.010, 0.030)}
_LENGTHS = {"index": (0.065, 0.040, 0.025, 0.020), "middle": (0.065, 0.045, 0.028, 0.020),
            "ring": (0.062, 0.042, 0.026, 0.020), "pinky": (0.055, 0.032, 0.020, 0.018),
            "thumb": (0.045, 0.032, 0.025)}
RADIUS_M = 0.008


def local_rotations(flexion, abduction, twist=None) -> np.ndarray:
    """(15, 3, 3) SMPL-X local rotations B Rz(flexion) Ry(abduction) Rx(twist) B^T (teleprev/human/smplx.py)."""
    twist = np.zeros(15) if twist is None else np.asarray(twist, dtype=float)
    out = np.empty((15, 3, 3))
    for j in range(15):
        turn = (
            axis_angle_to_matrix(np.array([0.0, 0.0, flexion[j]]))
            @ axis_angle_to_matrix(np.array([0.0, abduction[j], 0.0]))
            @ axis_angle_to_matrix(np.array([twist[j], 0.0, 0.0]))
        )
        out[j] = B[j] @ turn @ B[j].T
    return out


def xr_hand(local: np.ndarray, wrist_frame: np.ndarray, wrist_position) -> np.ndarray:
    """(25, 8) WebXR joints (position, quaternion x y z w, radius) of a right hand: `local` (15, 3, 3) SMPL-X
    local rotations, `wrist_frame` the hand's frame in the reference space (SMPL-X axes), and its position."""
    frames: dict[str, np.ndarray] = {"wrist": wrist_frame}
    positions: dict[str, np.ndarray] = {"wrist": np.asarray(wrist_position, dtype=float)}
    for finger, chain in hands._FINGER_CHAIN.items():
        names = chain if finger != "thumb" else chain[1:]
        tip = names[-1].rsplit("-", 2)[0] + "-tip" if finger != "thumb" else "thumb-tip"
        base = positions["wrist"] + wrist_frame @ np.array(_BASE[finger])
        if finger == "thumb":
            frame = wrist_frame @ local[smplx.JOINT_INDEX["thumb1"]] @ B[smplx.JOINT_INDEX["thumb1"]]
            rotations = [frame]
            for k in (2, 3):
                j = smplx.JOINT_INDEX[f"thumb{k}"]
                frame = frame @ B[j].T @ local[j] @ B[j]
                rotations.append(frame)
        else:
            frame = wrist_frame
            rotations = [frame]
            for k in (1, 2, 3):
                frame = frame @ local[smplx.JOINT_INDEX[f"{finger}{k}"]]
                rotations.append(frame)
        position = base
        for name, rotation, length in zip((*names, tip), (*rotations, rotations[-1]), (*_LENGTHS[finger], 0.0)):
            frames[name], positions[name] = rotation, position
            position = position + rotation @ np.array([-length, 0.0, 0.0])  # a bone runs along the frame's -x
    joints = np.zeros((25, 8))
    for name, i in hands.JOINT_INDEX.items():
        joints[i, :3] = positions[name]
        joints[i, 3:7] = matrix_to_quat(frames[name] @ hands.M)  # WebXR joint axes: R = G M
        joints[i, 7] = RADIUS_M
    return joints


def from_glove_and_suit(hand_pose: np.ndarray, wrist_position, wrist_quat, lift=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(25, 8) joints of the hand a glove (SMPL-X pose, (45,)) and a suit (wrist pose in the suit frame)
    recorded, as a headset in the suit's place would see it; `lift` is added in the reference space."""
    local = axis_angle_to_matrix(np.asarray(hand_pose, dtype=float).reshape(15, 3))
    frame = hands.A.T @ quat_to_matrix(wrist_quat)
    return xr_hand(local, frame, hands.A.T @ np.asarray(wrist_position, dtype=float) + np.asarray(lift))


def matrices(joints: np.ndarray) -> np.ndarray:
    """(25 * 16,) column-major 4x4 matrices of (25, 8) joints, as IWER's joint spaces hold them."""
    out = np.zeros((25, 4, 4))
    out[:, :3, :3] = quat_to_matrix(joints[:, 3:7])
    out[:, :3, 3] = joints[:, :3]
    out[:, 3, 3] = 1.0
    return np.swapaxes(out, 1, 2).reshape(-1)


XR_X = np.diag([-1.0, 1.0, 1.0])  # the reference space mirrored left <-> right (x is the operator's right)


def mirror_in_xr(joints: np.ndarray) -> np.ndarray:
    """A hand's joints as its mirror image's, written out from the definition: positions x -> -x, and each
    joint frame's bone (-z) and back (+y) mirrored, its x = y cross z again."""
    out = np.array(joints, dtype=float)
    for k in range(len(out)):
        out[k, :3] = XR_X @ out[k, :3]
        r = quat_to_matrix(out[k, 3:7])
        y, z = XR_X @ r[:, 1], XR_X @ r[:, 2]
        out[k, 3:7] = matrix_to_quat(np.column_stack([np.cross(y, z), y, z]))
    return out
