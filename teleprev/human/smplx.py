"""SMPL-X joint names and teleprev's convention for reading finger angles out of hand rotations.

Only the joint tree is needed (no SMPL-X model files). A hand pose is the 15 hand joints' local rotations
as axis-angle vectors (SMPL-X's `right_hand_pose`, shape (15, 3)), recorded as a JointSample of 45
values named "<joint>.x", "<joint>.y", "<joint>.z".

Convention (right hand, SMPL-X rest pose): the fingers point along -x, the palm faces -y and the thumb
side is +z. Each joint has a joint frame B in which flexion is a rotation about z (positive curls towards
the palm) and abduction a rotation about y (positive towards the thumb); the local rotation is
    R = B @ Rz(flexion) @ Ry(abduction) @ Rx(twist) @ B.T
flexion first, then abduction about the flexed segment's own y, then a twist about the bone. The bone
(along -x in B) points where flexion and abduction put it, whatever the twist: flexion is the bone's turn
in the plane of curling, abduction its angle out of that plane. So a deep fist's sideways deviation of a
few degrees reads as a few degrees, and a thumb metacarpal turned about its own bone reads the same at
every turn. angles_from_hand_pose reads the bone's direction. For the four fingers B is the identity; the
thumb's frame is the finger frame turned 60 degrees about y, so the thumb points out and forwards and
curls across the palm.

Sessions recorded by earlier versions read hands the other way round, R = B Ry(abduction) Rz(flexion) Rx(twist) B.T
(abduction first, the twist nearest zero taken off): angles_from_hand_pose_abduction_first, kept as it was
so that they re-run bit for bit (teleprev/pipeline/older_formats/ picks it). It is singular at 90 degrees of flexion
(a small sideways deviation of a
flexed finger reads as a large abduction) and flips a thumb turned more than 90 degrees about its bone.
"""

from __future__ import annotations

import functools

import numpy as np

FINGERS = ("index", "middle", "pinky", "ring", "thumb")
HAND_JOINTS: tuple[str, ...] = tuple(f"{f}{i}" for f in FINGERS for i in (1, 2, 3))
HAND_POSE_NAMES: tuple[str, ...] = tuple(f"{j}.{c}" for j in HAND_JOINTS for c in "xyz")
JOINT_INDEX = {j: i for i, j in enumerate(HAND_JOINTS)}

# SMPL-X body joints (the first 22 of the skeleton); SMPL's 24 add left_hand and right_hand.
BODY_JOINTS: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
    "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
)

_THUMB_TILT = np.deg2rad(60.0)


def _joint_frames() -> np.ndarray:
    frames = np.tile(np.eye(3), (len(HAND_JOINTS), 1, 1))
    c, s = np.cos(_THUMB_TILT), np.sin(_THUMB_TILT)
    thumb = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    for j in ("thumb1", "thumb2", "thumb3"):
        frames[JOINT_INDEX[j]] = thumb
    return frames


JOINT_FRAMES = _joint_frames()  # (15, 3, 3)
# The joint frames as (cos, sin) of their turn about y, for angles_from_hand_pose.
_FRAME_COS = np.array([np.cos(_THUMB_TILT) if j.startswith("thumb") else 1.0 for j in HAND_JOINTS])
_FRAME_SIN = np.array([np.sin(_THUMB_TILT) if j.startswith("thumb") else 0.0 for j in HAND_JOINTS])
FRAME_TURN = np.stack([_FRAME_COS, _FRAME_SIN])  # (2, 15): the same, for the compiled preparation


def hand_pose_from_angles(flexion: np.ndarray, abduction: np.ndarray, abduction_first: bool = False) -> np.ndarray:
    """Axis-angle hand pose (..., 15, 3) from flexion and abduction angles (..., 15) in radians.

    The rotation B Rz(flexion) Ry(abduction) B^T in closed form: the quaternion (x y z, w) of Rz(f) Ry(a)
    is (-sin a/2 sin f/2, sin a/2 cos f/2, cos a/2 sin f/2, cos a/2 cos f/2), and conjugating by the joint
    frame turns its vector part by B. Taken the short way round (w >= 0). A glove streams this at 120 Hz.
    `abduction_first`: B Ry(abduction) Rz(flexion) B^T instead (x = +sin a/2 sin f/2), the convention that
    angles_from_hand_pose_abduction_first (older session formats) inverts.
    """
    flexion = np.asarray(flexion, dtype=float)
    abduction = np.asarray(abduction, dtype=float)
    sa, ca = np.sin(0.5 * abduction), np.cos(0.5 * abduction)
    sf, cf = np.sin(0.5 * flexion), np.cos(0.5 * flexion)
    x = sa * sf if abduction_first else -(sa * sf)
    v = np.einsum("jik,...jk->...ji", JOINT_FRAMES, np.stack([x, sa * cf, ca * sf], axis=-1))
    w = ca * cf
    sign = np.where(w < 0, -1.0, 1.0)
    v, w = v * sign[..., None], np.abs(w)
    s = np.sqrt((v * v).sum(axis=-1))
    safe = np.where(s > 1e-12, s, 1.0)
    return v * np.where(s > 1e-12, 2.0 * np.arctan2(s, w) / safe, 2.0)[..., None]


def angles_from_hand_pose(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(flexion, abduction) angles (..., 15) from an axis-angle hand pose (..., 15, 3): the direction of
    each joint's bone.

    In the joint frame, M = B.T R B = Rz(flexion) Ry(abduction) Rx(twist), and the bone (x) points along
    M's first column (cos f cos a, sin f cos a, -sin a), which no twist moves: flexion = atan2(M10, M00)
    (past 90 degrees too), abduction = atan2(-M20, hypot(M00, M10)). Singular only where the bone points
    straight sideways (abduction 90 degrees), which no finger does. M's column from R's quaternion with
    its vector part turned by B.T (a rotation about y), column by column because it runs on every step;
    teleprev/kernels/glove.py computes the same in compiled code.
    """
    x, y, z, w = _joint_frame_quaternion(pose)
    m00 = 1.0 - 2.0 * (y * y + z * z)
    m10 = 2.0 * (x * y + z * w)
    m20 = 2.0 * (x * z - y * w)
    flexion = np.arctan2(m10, m00)
    abduction = np.arctan2(-m20, np.sqrt(m00 * m00 + m10 * m10))
    return flexion, abduction


def _joint_frame_quaternion(pose: np.ndarray):
    """(x, y, z, w), each (..., 15): the quaternion of each joint's rotation in its joint frame, B.T R B."""
    v = np.asarray(pose, dtype=float)
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    angle = np.sqrt(vx * vx + vy * vy + vz * vz)
    half = 0.5 * angle
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    w = np.cos(half)
    x0, y, z0 = vx * scale, vy * scale, vz * scale
    return _FRAME_COS * x0 - _FRAME_SIN * z0, y, _FRAME_SIN * x0 + _FRAME_COS * z0, w


def angles_from_hand_pose_abduction_first(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(flexion, abduction) angles (..., 15) from an axis-angle hand pose (..., 15, 3), as older
    session formats read them (teleprev/pipeline/older_formats): abduction first. Kept unchanged.

    In the joint frame, M = B.T R B = Ry(abduction) Rz(flexion) Rx(twist): the bone (along x) points
    where abduction and flexion put it, and twist turns the segment about its own bone. IMU gloves report
    full segment orientations, so twist is real there and must not leak into abduction: the twist is
    taken off first (the solution of the two that is nearest zero, so flexion may pass 90 degrees), then
    flexion = atan2(M10, M11), abduction = atan2(M02, M22). Twists below TWIST_NOISE are float noise of a
    twist-free pose and are left alone, so such poses give exactly the angles they always gave (recorded
    sessions reproduce bit for bit). Everything is computed from M's quaternion: R's quaternion with its
    vector part turned by B.T (a rotation about y), column by column because it runs on every step.
    """
    x, y, z, w = _joint_frame_quaternion(pose)
    w, x, y, z = _untwist(w, x, y, z)
    flexion = np.arctan2(2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z))
    abduction = np.arctan2(2.0 * (x * z + y * w), 1.0 - 2.0 * (x * x + y * y))
    return flexion, abduction


TWIST_NOISE = 1e-9  # rad


def _untwist(w, x, y, z):
    """The quaternion of M Rx(-twist) for M = Ry(a) Rz(f) Rx(twist) given as (w, x, y, z)."""
    m11 = 1.0 - 2.0 * (x * x + z * z)
    m12 = 2.0 * (y * z - x * w)
    twist = np.arctan2(-m12, m11)
    # twist and twist +- pi describe the same bone direction (flexion f or pi - f): take the smaller twist
    twist = np.where(twist > 0.5 * np.pi, twist - np.pi, np.where(twist < -0.5 * np.pi, twist + np.pi, twist))
    moved = np.abs(twist) > TWIST_NOISE
    if not np.any(moved):
        return w, x, y, z
    twist = np.where(moved, twist, 0.0)
    c, s = np.cos(0.5 * twist), np.sin(0.5 * twist)
    turned = w * c + x * s, x * c - w * s, y * c - z * s, z * c + y * s
    if w.ndim < 2:
        return turned
    # a batch of poses: each pose as if alone, so the twist-free ones keep their bits exactly
    posed = np.any(moved, axis=-1)[..., None]
    return tuple(np.where(posed, new, old) for new, old in zip(turned, (w, x, y, z)))


@functools.lru_cache(maxsize=64)
def _order(names: tuple[str, ...]) -> np.ndarray:
    index = {n: i for i, n in enumerate(names)}
    missing = [n for n in HAND_POSE_NAMES if n not in index]
    if missing:
        raise KeyError(f"hand pose is missing {len(missing)} components, e.g. {missing[:3]}")
    return np.array([index[n] for n in HAND_POSE_NAMES])


def hand_values(names: tuple[str, ...], values: np.ndarray) -> np.ndarray:
    """The 45 values in HAND_POSE_NAMES order from named values (any order); KeyError when some are
    missing. Names already in that order (every glove plugin's) cost no look-up, and the answer may then
    be `values` itself: read it, do not write it."""
    if names is HAND_POSE_NAMES or names is _SAME_ORDER[0] or (isinstance(names, tuple) and names == HAND_POSE_NAMES):
        v = np.asarray(values, dtype=float)
        if v.shape == (45,):
            _SAME_ORDER[0] = names  # a decoder hands the same tuple to every sample: compared once
            return v
    return np.asarray(values, dtype=float)[_order(tuple(names))]


_SAME_ORDER: list = [HAND_POSE_NAMES]  # the last names tuple found equal to HAND_POSE_NAMES


def hand_pose_from_values(names: tuple[str, ...], values: np.ndarray) -> np.ndarray:
    """A (15, 3) hand pose from named values (any order), as recorded in a JointSample."""
    v = hand_values(names, values)
    return (v.copy() if v is values else v).reshape(15, 3)
