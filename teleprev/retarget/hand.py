"""SMPL-X hand -> LEAP Hand, joint to joint.

Each LEAP joint takes one angle of one SMPL-X hand joint (its flexion or abduction, see
teleprev/human/smplx.py), times a sign and a scale, plus an offset, clamped to the joint's limits. The
defaults map the human's angles one to one; a calibration (teleprev calibrate) adjusts scale and offset.
The LEAP Hand has three fingers and a thumb, so the pinky is not used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from teleprev.human.smplx import JOINT_INDEX, angles_from_hand_pose
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class JointMap:
    source: str  # SMPL-X hand joint, e.g. "index1"
    angle: Literal["flexion", "abduction"]
    sign: float = 1.0
    scale: float = 1.0
    offset: float = 0.0


def _finger(base: int, name: str) -> dict[str, JointMap]:
    # SMPL-X abduction is positive towards the thumb, the LEAP side-to-side joint the other way.
    return {
        str(base): JointMap(f"{name}1", "abduction", -1.0),
        str(base + 1): JointMap(f"{name}1", "flexion"),
        str(base + 2): JointMap(f"{name}2", "flexion"),
        str(base + 3): JointMap(f"{name}3", "flexion"),
    }


DEFAULT_LEAP_MAP: dict[str, JointMap] = {
    **_finger(0, "index"),
    **_finger(4, "middle"),
    **_finger(8, "ring"),
    "12": JointMap("thumb1", "abduction", -1.0),
    "13": JointMap("thumb1", "flexion"),
    "14": JointMap("thumb2", "flexion"),
    "15": JointMap("thumb3", "flexion"),
}


class LeapRetargeter:
    """Maps an axis-angle SMPL-X hand pose (15, 3) to LEAP joint positions in the model's joint order."""

    def __init__(self, hand: RobotModel, mapping: dict[str, JointMap] | None = None):
        mapping = mapping or DEFAULT_LEAP_MAP
        self.hand = hand
        self.mapping = mapping
        order = hand.indices(list(mapping))
        maps = list(mapping.values())
        # angles are stacked as [flexion(15), abduction(15)]
        src = np.array([JOINT_INDEX[m.source] + (15 if m.angle == "abduction" else 0) for m in maps])
        gain = np.array([m.sign * m.scale for m in maps])
        offset = np.array([m.offset for m in maps])
        n = len(hand.joint_names)
        self._src = np.zeros(n, dtype=int)
        self._gain = np.zeros(n)
        self._offset = np.zeros(n)
        self._src[order], self._gain[order], self._offset[order] = src, gain, offset

    def table(self) -> np.ndarray:
        """The mapping as the compiled preparation takes it (teleprev/kernels/glove.py): rows
        source angle index (into [flexion(15), abduction(15)]), gain, offset, lower and upper limit, one
        column per joint in the model's order."""
        return np.ascontiguousarray(np.stack([self._src.astype(float), self._gain, self._offset,
                                              self.hand.lower, self.hand.upper]), dtype=float)

    def from_angles(self, flexion: np.ndarray, abduction: np.ndarray) -> np.ndarray:
        """Joint values, clamped to the limits, from finger angles (..., 15) as angles_from_hand_pose gives."""
        angles = np.concatenate([flexion, abduction], axis=-1)
        return self.hand.clip(angles[..., self._src] * self._gain + self._offset)

    def __call__(self, hand_pose: np.ndarray) -> np.ndarray:
        """Joint values for one pose (15, 3) or a batch (..., 15, 3)."""
        return self.from_angles(*angles_from_hand_pose(hand_pose))
