"""Wrist motion to arm joints.

The robot's tool point (TCP) follows the operator's wrist *relative to an anchor*: when the anchor is
set, the wrist pose W0 and the robot's TCP pose T0 are remembered, and afterwards

    position    p = p(T0) + scale * M (p(W) - p(W0))           clipped to the rig's workspace box
    orientation R = (M R(W) R(W0)^T M^T) R(T0)

where M turns the suit's world frame into the robot's base frame (a calibrated rotation; identity when
both have x forward and z up). The anchor is set when preview begins; the robot does not move in
preview, so T0 is also its pose when execution is engaged. The joints come from the warm-started IK.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.robot.ik import ArmIK, IkResult


@dataclass(frozen=True)
class Anchor:
    wrist: np.ndarray  # 4x4, suit frame
    tcp: np.ndarray  # 4x4, robot base frame


class ArmRetargeter:
    def __init__(
        self,
        ik: ArmIK,
        scale: float = 1.0,
        workspace_min=(-np.inf,) * 3,
        workspace_max=(np.inf,) * 3,
        suit_to_robot: np.ndarray | None = None,
    ):
        from teleprev.kernels.ik import Workspace

        self.ik = ik
        self.scale = scale
        # own float64 copies: the kernels take these as they are
        self.lo = np.array(workspace_min, dtype=float)
        self.hi = np.array(workspace_max, dtype=float)
        self.m = np.eye(3) if suit_to_robot is None else np.array(suit_to_robot, dtype=float)
        self._workspace = Workspace(self.m, float(self.scale), self.lo, self.hi)
        q = ik.chain.neutral()  # load the kernels from numba's cache now, not in a live loop's first steps
        pose = ik.pose(q)
        self.solve(self.anchor(pose, q), pose, q)
        self.target(self.anchor(pose, q), pose)

    def anchor(self, wrist: np.ndarray, arm_q: np.ndarray) -> Anchor:
        return Anchor(np.array(wrist, dtype=float), self.ik.pose(arm_q))

    def target(self, anchor: Anchor, wrist: np.ndarray) -> tuple[np.ndarray, bool]:
        """The TCP target pose, and whether the workspace box clipped it (ik_kernels.arm_target_into)."""
        from teleprev.kernels import ik as ik_kernels

        t = np.empty((4, 4))
        clipped = ik_kernels.arm_target_into(*self._kernel_args(anchor, wrist), t)
        return t, bool(clipped)

    def _kernel_args(self, anchor: Anchor, wrist: np.ndarray) -> tuple:
        """ik_kernels.arm_target_into's inputs. The anchor's arrays (anchor() made them) and m, lo, hi are
        writeable float64 already; the wrist is copied, since a read-only or other-typed array would make
        numba compile another signature (seconds, in the live loop)."""
        return anchor.wrist, anchor.tcp, np.array(wrist, dtype=np.float64), *self._workspace

    def solve(self, anchor: Anchor, wrist: np.ndarray, q_start: np.ndarray) -> tuple[IkResult, bool]:
        """The target and the IK in one compiled call (ik_kernels.arm_solve): the solution, and whether the
        workspace box clipped the target."""
        from teleprev.kernels import ik as ik_kernels

        q, converged, iterations, pos_err, rot_err, clipped = ik_kernels.arm_solve(
            *self._kernel_args(anchor, wrist), np.array(q_start, dtype=np.float64), *self.ik.kernel_args)
        return IkResult(q, converged, iterations, pos_err, rot_err), bool(clipped)
