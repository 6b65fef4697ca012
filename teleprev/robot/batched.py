"""Batched forward kinematics on pytorch-kinematics, for data generation on a CPU or a GPU.

The chain is built from our own parsed model rather than pytorch-kinematics' URDF loader, because that
loader rounds joint origins through float32 quaternions (about 1e-8 m of error); built this way the
chain is float64 throughout and agrees with RobotModel.fk to well below 1e-9 m. Imports torch: keep it
out of the live path.
"""

from __future__ import annotations

import numpy as np
import pytorch_kinematics as pk
import torch
from pytorch_kinematics import frame as pk_frame
from pytorch_kinematics.transforms import Transform3d

from teleprev.robot.model import LinkPoses, RobotModel


class BatchedKinematics:
    def __init__(self, model: RobotModel, device: str | torch.device = "cpu", dtype: torch.dtype = torch.float64):
        if any(j.mimic is not None for j in model.desc.joints):
            raise ValueError(f"{model.name}: mimic joints are not supported by the batched path")
        self.model = model
        self.device = torch.device(device)
        self.dtype = dtype
        self.chain = pk.Chain(self._frame(model.desc.root), dtype=dtype, device=self.device)
        names = self.chain.get_joint_parameter_names()
        # pytorch-kinematics orders joints depth-first; map ours to its order by name.
        self._to_chain = torch.as_tensor(model.indices(names), device=self.device)
        self._link_order = list(model.link_names)

    def _frame(self, link_name: str) -> pk_frame.Frame:
        model = self.model
        joint = model.parent_joint.get(link_name)
        if joint is None:
            pk_joint = pk_frame.Joint(dtype=self.dtype, device=self.device)
        else:
            offset = Transform3d(matrix=torch.as_tensor(joint.origin[None], dtype=self.dtype), dtype=self.dtype)
            kind = "revolute" if joint.type == "continuous" else joint.type
            pk_joint = pk_frame.Joint(
                joint.name, offset=offset, joint_type=kind, axis=tuple(joint.axis),
                dtype=self.dtype, device=self.device, limits=(joint.lower, joint.upper),
            )
        frame = pk_frame.Frame(link_name, link=pk_frame.Link(link_name), joint=pk_joint)
        # Frame(children=...) is ignored by pytorch-kinematics 0.10, so attach them one by one.
        for j in model.desc.joints:
            if j.parent == link_name:
                frame.add_child(self._frame(j.child))
        return frame

    def fk_tensor(self, q: torch.Tensor) -> torch.Tensor:
        """Link transforms (N, L, 4, 4) in the model's link order, for joint vectors (N, n) in its joint order."""
        th = q[:, self._to_chain]
        frames = self.chain.forward_kinematics(th)
        return torch.stack([frames[name].get_matrix() for name in self._link_order], dim=1)

    def fk(self, q: np.ndarray) -> LinkPoses:
        qt = torch.as_tensor(np.atleast_2d(q), dtype=self.dtype, device=self.device)
        with torch.no_grad():
            world = self.fk_tensor(qt).cpu().numpy()
        if np.ndim(q) == 1:
            world = world[0]
        return LinkPoses(world, self.model.link_index)
