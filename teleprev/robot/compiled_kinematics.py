"""Forward kinematics in compiled code (teleprev.kernels.fk), for any tree of fixed, revolute and
prismatic joints given as a RobotModel. Same link order and transforms as RobotModel.fk (to rounding).
"""

from __future__ import annotations

import numpy as np

from teleprev.kernels import fk as fk_kernels
from teleprev.robot.model import LinkPoses, RobotModel


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


class CompiledKinematics:
    """The kernels' FK table for one model (fk_kernels.FkTable)."""

    def __init__(self, model: RobotModel):
        self.model = model
        n = len(model.link_names)
        self.link_int = np.zeros((n, 3), dtype=np.int64)
        self.link_num = np.zeros((n, 2))
        self.link_terms = np.zeros((n, 4, 3, 4))
        self.link_terms[0, 0, :, :3] = np.eye(3)
        for i, name in enumerate(model.link_names[1:], start=1):
            j = model.parent_joint[name]
            rot = j.origin[:3, :3]
            self.link_int[i, 0] = model.link_index[j.parent]
            self.link_terms[i, 0] = j.origin[:3]
            if j.type == "fixed":
                continue  # kind FIXED, driven by nothing
            if j.type == "prismatic":
                self.link_int[i, 2] = fk_kernels.PRISMATIC
                self.link_terms[i, 3, :, 3] = rot @ j.axis
            else:  # revolute and continuous: R(a) = I + sin(a) K + (1 - cos(a)) K^2
                self.link_int[i, 2] = fk_kernels.REVOLUTE
                k = _skew(j.axis)
                self.link_terms[i, 1, :, :3] = rot @ k
                self.link_terms[i, 2, :, :3] = rot @ k @ k
            if j.mimic is None:
                self.link_int[i, 1], self.link_num[i] = model.joint_index[j.name], (1.0, 0.0)
            else:
                self.link_int[i, 1] = model.joint_index[j.mimic.joint]
                self.link_num[i] = (j.mimic.multiplier, j.mimic.offset)
        self.table = fk_kernels.FkTable(self.link_int, self.link_num, self.link_terms)

    def world(self, q: np.ndarray) -> np.ndarray:
        """Link transforms (L, 4, 4) of one configuration (n,), or (N, L, 4, 4) of a batch (N, n)."""
        q = np.ascontiguousarray(q, dtype=np.float64)
        if q.ndim == 1:
            return fk_kernels.fk(q, *self.table)
        flat = q.reshape(-1, q.shape[-1])
        world = fk_kernels.fk_batch(flat, *self.table)
        return world.reshape(q.shape[:-1] + world.shape[1:])

    def fk(self, q: np.ndarray) -> LinkPoses:
        """RobotModel.fk's answer, computed by the kernel."""
        return LinkPoses(self.world(q), self.model.link_index)
