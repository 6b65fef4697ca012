"""A robot's link frames as parent -> child transforms, the way Foxglove's URDF panel reads /tf."""

from __future__ import annotations

import numpy as np

from teleprev.messages import Transform, TransformsSample
from teleprev.robot.model import RobotModel
from teleprev.transforms import matrix_to_quat


class FramePublisher:
    def __init__(self, model: RobotModel, sensors: tuple[Transform, ...] = ()):
        """`sensors`: fixed frames (cameras, the suit's world) hung on the robot's links, sent with every sample."""
        self.model = model
        self.sensors = tuple(sensors)
        self._joints = [j for j in model.desc.joints]
        self._parent = np.array([model.link_index[j.parent] for j in self._joints])
        self._child = np.array([model.link_index[j.child] for j in self._joints])

    def sample(self, q: np.ndarray, stamp_ns: int) -> TransformsSample:
        world = self.model.fk(q).world
        local = np.linalg.inv(world[self._parent]) @ world[self._child]
        return TransformsSample(
            stamp_ns,
            tuple(
                Transform(j.parent, j.child, local[i, :3, 3].copy(), matrix_to_quat(local[i, :3, :3]))
                for i, j in enumerate(self._joints)
            ) + self.sensors,
        )
