"""Arm inverse kinematics: damped least squares, warm-started, never outside the joint limits."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class IkResult:
    q: np.ndarray
    converged: bool
    iterations: int
    position_error: float  # metres
    rotation_error: float  # radians


class ArmIK:
    """Solves for the joints of the serial chain from the model's root to `tip`.

    `tcp` is a fixed transform from the tip link to the point being placed (for example a palm centre).
    Each iteration takes a damped least-squares step on the 6-D pose error, caps the step size and
    clips to the joint limits, so every iterate (and the result) is within limits. The solver is one numba
    kernel (teleprev.kernels.ik.ik_solve: the 6x6 system by Cholesky; the same inputs always give the same
    bits); older sessions solved by numpy re-run with teleprev.pipeline.older_formats.NumpyArmIK.
    """

    def __init__(
        self,
        model: RobotModel,
        tip: str,
        tcp: np.ndarray | None = None,
        position_tolerance: float = 5e-4,
        rotation_tolerance: float = 5e-3,
        max_iterations: int = 60,
        damping: float = 1e-6,
        max_step: float = 0.4,
        retry: bool = True,
    ):
        full = model.chain_to(tip)
        self.joint_names = full.joint_names
        self.tip = tip
        # Fixed joints after the last actuated one are folded into a constant tool transform, so each FK
        # evaluates only the moving part of the chain.
        last = next(j for j in reversed(full.desc.joints) if j.type != "fixed")
        fixed = np.eye(4)
        for j in full.desc.joints[full.desc.joints.index(last) + 1:]:
            fixed = fixed @ j.origin
        self.chain = full.chain_to(last.child)
        self.tcp = fixed @ (np.eye(4) if tcp is None else np.asarray(tcp, dtype=float))
        self.position_tolerance = position_tolerance
        self.rotation_tolerance = rotation_tolerance
        self.max_iterations = max_iterations
        self.damping = damping
        self.max_step = max_step
        self.retry = retry  # a second, short-stepped try from the start when the first does not converge
        self._tip_index = self.chain.link_index[last.child]
        self._joint_links = np.array([self.chain.link_index[j.child] for j in self.chain.joints])
        self._axes = np.array([j.axis for j in self.chain.joints])
        self._revolute = np.array([j.type != "prismatic" for j in self.chain.joints])
        self.kernel_args = self._kernel_args()  # ik_kernels.ik_solve's arguments after target and q_start
        q = self.chain.neutral()  # load the kernel from numba's cache now, not in a live loop's first steps
        self.solve(self.pose(q), q)

    def _kernel_args(self) -> tuple:
        """The solver's tables and settings: FkTable, IkChain, IkSettings."""
        from teleprev.kernels.ik import IkChain, IkSettings
        from teleprev.robot.compiled_kinematics import CompiledKinematics

        c = np.ascontiguousarray
        chain = IkChain(int(self._tip_index), c(self.tcp, dtype=np.float64), c(self._joint_links, dtype=np.int64),
                        c(self._axes, dtype=np.float64), c(self._revolute, dtype=np.bool_),
                        c(self.chain.lower, dtype=np.float64), c(self.chain.upper, dtype=np.float64))
        settings = IkSettings(float(self.position_tolerance), float(self.rotation_tolerance), int(self.max_iterations),
                              float(self.damping), float(self.max_step), bool(self.retry))
        return (*CompiledKinematics(self.chain).table, *chain, *settings)

    def pose(self, q: np.ndarray) -> np.ndarray:
        """The TCP pose (4x4) for arm joints q."""
        return self.chain.fk(q).world[self._tip_index] @ self.tcp

    def solve(self, target: np.ndarray, q_start: np.ndarray) -> IkResult:
        from teleprev.kernels import ik as ik_kernels

        # fresh writeable float64 copies: a read-only array (a decoded message) would make numba compile
        # another signature, seconds in the live loop
        q, converged, iterations, pos_err, rot_err = ik_kernels.ik_solve(
            np.array(target, dtype=np.float64), np.array(q_start, dtype=np.float64), *self.kernel_args)
        return IkResult(q, converged, iterations, pos_err, rot_err)
