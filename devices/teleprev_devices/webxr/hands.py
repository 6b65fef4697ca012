"""WebXR hand joints into teleprev's frames and the SMPL-X hand pose.

WebXR (Hand Input Module, level 1) gives 25 joints per hand, each a pose in the session's reference
space: the joint's -z points along its bone towards the fingertip and its +y out of the back of the hand,
x = y cross z. teleprev's SMPL-X convention (teleprev/human/smplx.py) puts a right hand's fingers along
-x, its back along +y and its thumb side along +z. So a vector v in a WebXR joint frame is M v in the
SMPL-X axes, with M sending x -> -z, y -> y, z -> x (a rotation: for a right hand the thumb is at -x).

The reference space ("local-floor") is y up, -z forward, x right; the suit frame, which the arm's
retargeting and `teleprev calibrate` already read, is x forward, y left, z up: A sends (x, y, z) to
(-z, -x, y). So the wrist pose published is p = A p_xr, R = A R_wrist M^T, and `teleprev calibrate`
finds the yaw between the headset's forward and the robot's as it does for a suit.

The hand pose is each SMPL-X joint's local rotation: with G_j = R_j M^T a bone frame in SMPL-X axes and
B_j the SMPL-X joint frame (the thumb's is turned, see smplx.JOINT_FRAMES), joint j under parent p turns
by B_p G_p^T G_j B_j^T. The parents are the bones before: the metacarpal for a finger's first joint, the
wrist for the thumb's. A whole-hand or wrist rotation therefore cancels, and the twist of a bone about
its own axis stays in the rotation, where the pipeline reads only the bone's direction
(smplx.angles_from_hand_pose): twist never reads as abduction, and a thumb metacarpal turned about
itself (IWER's pinch: about -105 degrees) reads as the same thumb.

The left hand is read through its mirror image, a right hand: positions and joint frames mirrored through
the reference space's x (a joint frame R becomes X R X, X = diag(-1, 1, 1), so that it is right-handed again
with -z along the bone and +y out of the back). The right hand's conversions then give the pose in the right
hand's terms, which is mirrored back into the left hand's own SMPL-X pose (what a left glove publishes; a
bimanual pipeline mirrors it again before retargeting), and the wrist, given as a mirrored right wrist
(teleprev/human/mirror.py: M R M in the suit frame, M = A X A^-1), as sim.suit and vmc.suit give a left one.
"""

from __future__ import annotations

import numpy as np

from teleprev.devices import body_mirror, smplx, transforms

FINGERS = ("thumb", "index-finger", "middle-finger", "ring-finger", "pinky-finger")
_PARTS = {"thumb": ("metacarpal", "phalanx-proximal", "phalanx-distal", "tip"),
          **{f: ("metacarpal", "phalanx-proximal", "phalanx-intermediate", "phalanx-distal", "tip")
             for f in FINGERS[1:]}}
# XRHandJoint, in the order of the enumeration (and of XRHand's iteration).
JOINTS: tuple[str, ...] = ("wrist", *(f"{f}-{p}" for f in FINGERS for p in _PARTS[f]))
JOINT_INDEX = {j: i for i, j in enumerate(JOINTS)}
HANDS = ("left", "right")
# One joint's values on the wire and in the recording: position (m), orientation (x y z w), radius (m).
JOINT_VALUES = ("px", "py", "pz", "qx", "qy", "qz", "qw", "r")
RAW_NAMES: tuple[str, ...] = tuple(f"{j}.{v}" for j in JOINTS for v in JOINT_VALUES)  # one hand's, recorded

M = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # WebXR joint axes -> SMPL-X hand axes
A = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # XR reference space -> suit frame
X = np.diag([-1.0, 1.0, 1.0])  # the mirror through the reference space's x: a left hand <-> a right hand
_X_QUAT = np.array([1.0, -1.0, -1.0, 1.0])  # X R X on a quaternion x y z w

_SMPLX_FINGER = {"index": "index-finger", "middle": "middle-finger", "ring": "ring-finger",
                 "pinky": "pinky-finger", "thumb": "thumb"}
_FINGER_CHAIN = {f: (f"{x}-metacarpal", f"{x}-phalanx-proximal", f"{x}-phalanx-intermediate",
                     f"{x}-phalanx-distal") for f, x in _SMPLX_FINGER.items() if f != "thumb"}
_FINGER_CHAIN["thumb"] = ("wrist", "thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal")


def _parents_and_children() -> tuple[np.ndarray, np.ndarray]:
    """For each SMPL-X hand joint (smplx.HAND_JOINTS order), the WebXR joints of its parent and its own bone."""
    parent, child = [], []
    for name in smplx.HAND_JOINTS:
        chain = _FINGER_CHAIN[name[:-1]]
        k = int(name[-1])
        parent.append(JOINT_INDEX[chain[k - 1]])
        child.append(JOINT_INDEX[chain[k]])
    return np.array(parent), np.array(child)


_PARENT, _CHILD = _parents_and_children()
_FRAMES = smplx.JOINT_FRAMES  # (15, 3, 3)
# The parent's SMPL-X joint frame: the thumb's for the thumb's second and third joints, else the identity.
_PARENT_FRAMES = np.array([_FRAMES[i] if name.startswith("thumb") and name[-1] != "1" else np.eye(3)
                           for i, name in enumerate(smplx.HAND_JOINTS)])


def bone_frames(joints: np.ndarray) -> np.ndarray:
    """(25, 3, 3): each joint's bone frame in SMPL-X axes, G = R M^T, from one hand's (25, 8) values."""
    return transforms.quat_to_matrix(joints[:, 3:7]) @ M.T


def hand_pose(joints: np.ndarray) -> np.ndarray:
    """(45,) SMPL-X right-hand pose (axis-angle per joint, smplx.HAND_POSE_NAMES order) from the right
    hand's (25, 8) joint values."""
    g = bone_frames(np.asarray(joints, dtype=float))
    local = _PARENT_FRAMES @ np.swapaxes(g[_PARENT], -1, -2) @ g[_CHILD] @ np.swapaxes(_FRAMES, -1, -2)
    return np.concatenate([transforms.matrix_to_axis_angle(r) for r in local])


def wrist_in_suit(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,), quaternion x y z w) of the SMPL-X right-hand frame in the suit frame, from the right
    hand's (25, 8) joint values."""
    wrist = np.asarray(joints[JOINT_INDEX["wrist"]], dtype=float)
    r = A @ transforms.quat_to_matrix(wrist[3:7]) @ M.T
    return A @ wrist[:3], transforms.matrix_to_quat(r)


def head_in_suit(head: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The headset's (position, quaternion) in the suit frame, from its (7,) pose in the reference space;
    its axes stay the viewer's (WebXR: -z the gaze, +y up)."""
    head = np.asarray(head, dtype=float)
    return A @ head[:3], transforms.matrix_to_quat(A @ transforms.quat_to_matrix(head[3:7]))


def mirrored_hand(joints: np.ndarray) -> np.ndarray:
    """(25, 8): one hand's joint values as its mirror image's (a left hand as a right one, and back)."""
    out = np.array(joints, dtype=float)
    out[:, :3] = out[:, :3] @ X
    out[:, 3:7] *= _X_QUAT
    return out


def side_hand_pose(joints: np.ndarray, side: str) -> np.ndarray:
    """(45,) the SMPL-X pose of the `side` hand (its own, as a glove of that hand gives it)."""
    if side == "right":
        return hand_pose(joints)
    return body_mirror.mirror_hand_pose(hand_pose(mirrored_hand(joints)))


def side_wrist_in_suit(joints: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """The `side` wrist's (position, quaternion) in the suit frame: the left one as a mirrored right wrist."""
    if side == "right":
        return wrist_in_suit(joints)
    position, quat = wrist_in_suit(mirrored_hand(joints))
    position, rotation = body_mirror.mirror_wrist(position, transforms.quat_to_matrix(quat))
    return position, transforms.matrix_to_quat(rotation)
