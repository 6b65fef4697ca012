"""The operator's left side in the right side's terms: a mirror through the body's sagittal plane.

A left glove reports the left hand's SMPL-X pose; retargeting (and the joint map calibrated for it) is written
for the right hand. SMPL-X's joint frames have x across the body, so the mirror through the sagittal plane
turns each joint's axis-angle a into det(M) M a = (a_x, -a_y, -a_z): the right-hand pose of the same
finger motion. A suit's world frame has y across the body (x forward, z up), so a wrist pose (p, R) mirrors to
(M p, M R M) with M = diag(1, -1, 1). Both are their own inverse.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from teleprev.human.smplx import HAND_POSE_NAMES

SUIT_MIRROR = np.diag([1.0, -1.0, 1.0])


def mirror_hand_pose(pose: np.ndarray, names: Sequence[str] = HAND_POSE_NAMES) -> np.ndarray:
    """SMPL-X hand-pose values of one hand as the other hand's, by component name ("<joint>.x|y|z")."""
    signs = np.array([1.0 if n.endswith(".x") else -1.0 for n in names])
    return np.asarray(pose, dtype=float) * signs


def mirror_wrist(position: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A wrist pose in the suit's frame as the other wrist's: (M p, M R M)."""
    return SUIT_MIRROR @ np.asarray(position, float), SUIT_MIRROR @ np.asarray(rotation, float) @ SUIT_MIRROR
