"""Unity's humanoid skeleton (as VMC sends it) into teleprev's frames and the SMPL-X conventions.

Unity is left-handed: x right, y up, z forward; a humanoid avatar faces +z, so its right arm in T-pose
points along +x, palm down (-y), thumb forward (+z). VMC senders stream *normalized* bone rotations
(VRM-style rigs: every bone's local rotation is the identity in T-pose and its axes are the avatar's),
so a bone's local quaternion is its rotation away from T-pose, in Unity axes. Unity's Quaternion * Vector3
uses the usual (right-handed) formula, so quat_to_matrix gives the matrix acting on Unity coordinates.

Two changes of coordinates, both reflections (det -1), applied as v' = A v and R' = A R A^-1:

  D = diag(-1, 1, 1)       Unity axes -> SMPL-X body axes (x left, y up, z forward, right-handed).
                           SMPL-X's right hand in rest: fingers -x, palm -y, thumb +z; Unity's right
                           hand in T-pose: fingers +x, palm -y, thumb +z. D maps one onto the other.
                           A local rotation becomes R_smplx = D R_unity D; for a quaternion
                           (x, y, z, w) -> (x, -y, -z, w). A finger curling towards the palm is a
                           negative turn about Unity z and a positive one about SMPL-X z (= flexion).

  C = [[0,0,1],[-1,0,0],[0,1,0]]   Unity world -> the suit's world frame (teleprev: x forward, y left,
                           z up, right-handed; the avatar faces +x): x = z_u, y = -x_u, z = y_u.

The wrist pose on /suit/<name>/wrist is the pose of the SMPL-X right-hand frame in the suit frame: a
vector h in the hand frame is D h in Unity bone axes, R_unity D h in Unity world, C R_unity D h in the
suit frame, so R_wrist = C R_unity D and p_wrist = C p_unity. In T-pose R_wrist = C D: fingers -> -y
(the operator's right), palm -> -z (down), thumb -> +x (forward).

The left side reads the Left* bones with the same conversions: the left finger bones give the SMPL-X left
hand's pose (D maps Unity's left fingers, -x in T-pose, onto SMPL-X's left ones, +x). The left wrist is
given as a right wrist mirrored through the body's sagittal plane (teleprev/human/mirror.py: M R M, with
M = diag(1, -1, 1) = C D C^-1 in the suit frame), which is what the left side's pipeline and the mirrored
left robot take (sim.suit's side = "left" gives the same). The mirror in Unity is D, so a mirrored
skeleton's left wrist is R' = D R D where the right one is R; C R' X = M C R D X equals the mirrored right
wrist M (C R D) M for X = M: R_wrist = C R_unity M, p_wrist = C p_unity.
"""

from __future__ import annotations

import numpy as np

from teleprev.devices import smplx, transforms

# UnityEngine.HumanBodyBones, in enum order.
HUMAN_BODY_BONES: tuple[str, ...] = (
    "Hips", "LeftUpperLeg", "RightUpperLeg", "LeftLowerLeg", "RightLowerLeg", "LeftFoot", "RightFoot",
    "Spine", "Chest", "Neck", "Head", "LeftShoulder", "RightShoulder", "LeftUpperArm", "RightUpperArm",
    "LeftLowerArm", "RightLowerArm", "LeftHand", "RightHand", "LeftToes", "RightToes", "LeftEye", "RightEye",
    "Jaw",
    *(f"{side}{finger}{part}" for side in ("Left", "Right")
      for finger in ("Thumb", "Index", "Middle", "Ring", "Little")
      for part in ("Proximal", "Intermediate", "Distal")),
    "UpperChest",
)
KNOWN_BONES = frozenset(HUMAN_BODY_BONES)

# Hips up the right arm. Optional bones (absent from many rigs, so not sent) are skipped: in Unity's
# hierarchy the next bone then hangs from the previous one directly.
RIGHT_ARM_CHAIN = (
    "Hips",
    "Spine",
    "Chest",
    "UpperChest",
    "RightShoulder",
    "RightUpperArm",
    "RightLowerArm",
    "RightHand",
)
RIGHT_ARM_REQUIRED = frozenset({"Hips", "Spine", "RightUpperArm", "RightLowerArm", "RightHand"})
ARM_CHAIN = {"right": RIGHT_ARM_CHAIN, "left": tuple(b.replace("Right", "Left") for b in RIGHT_ARM_CHAIN)}
ARM_REQUIRED = {"right": RIGHT_ARM_REQUIRED, "left": frozenset(b.replace("Right", "Left") for b in RIGHT_ARM_REQUIRED)}

_FINGER_BONE = {"index": "Index", "middle": "Middle", "pinky": "Little", "ring": "Ring", "thumb": "Thumb"}
_PART = {"1": "Proximal", "2": "Intermediate", "3": "Distal"}
# SMPL-X hand joint -> Unity bone, in smplx.HAND_JOINTS order (index1 <- RightIndexProximal, ...).
RIGHT_HAND_BONES: tuple[str, ...] = tuple(f"Right{_FINGER_BONE[j[:-1]]}{_PART[j[-1]]}" for j in smplx.HAND_JOINTS)
HAND_BONES = {"right": RIGHT_HAND_BONES, "left": tuple(b.replace("Right", "Left") for b in RIGHT_HAND_BONES)}

# SMPL-X body joint -> Unity bone, in smplx.BODY_JOINTS order; pelvis is the global orientation (root * Hips).
BODY_BONES: tuple[str, ...] = tuple({
    "pelvis": "Hips", "left_hip": "LeftUpperLeg", "right_hip": "RightUpperLeg", "spine1": "Spine",
    "left_knee": "LeftLowerLeg", "right_knee": "RightLowerLeg", "spine2": "Chest", "left_ankle": "LeftFoot",
    "right_ankle": "RightFoot", "spine3": "UpperChest", "left_foot": "LeftToes", "right_foot": "RightToes",
    "neck": "Neck", "left_collar": "LeftShoulder", "right_collar": "RightShoulder", "head": "Head",
    "left_shoulder": "LeftUpperArm", "right_shoulder": "RightUpperArm", "left_elbow": "LeftLowerArm",
    "right_elbow": "RightLowerArm", "left_wrist": "LeftHand", "right_wrist": "RightHand",
}[j] for j in smplx.BODY_JOINTS)

D = np.diag([-1.0, 1.0, 1.0])
C = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
M = np.diag([1.0, -1.0, 1.0])  # the mirror through the sagittal plane, in the suit frame (= C D C^-1)
_D_QUAT = np.array([1.0, -1.0, -1.0, 1.0])  # D R D on a quaternion x y z w


def local_rotations_to_smplx(quats: np.ndarray) -> np.ndarray:
    """Unity local rotations (..., 4) x y z w -> SMPL-X axis-angle (..., 3): D R D."""
    return transforms.quat_to_axis_angle(np.asarray(quats, dtype=float) * _D_QUAT)


def transform(position: np.ndarray, quat: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = transforms.quat_to_matrix(quat)
    t[:3, 3] = position
    return t


def chain(root: np.ndarray, locals_: list[np.ndarray]) -> np.ndarray:
    """A bone's world transform in Unity coordinates: root, then each local transform from Hips down."""
    t = root
    for local in locals_:
        t = t @ local
    return t


def wrist_in_suit(world_unity: np.ndarray, side: str = "right") -> tuple[np.ndarray, np.ndarray]:
    """(position (3,), quaternion x y z w) of the SMPL-X right-hand frame in the suit frame; of the left hand,
    that frame mirrored (see the module's docstring)."""
    return C @ world_unity[:3, 3], transforms.matrix_to_quat(C @ world_unity[:3, :3] @ (D if side == "right" else M))
