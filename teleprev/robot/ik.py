"""Arm inverse kinematics: damped least squares, warm-started, never outside the joint limits."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.robot.model import RobotModel
from teleprev.transforms import rotation_error


_EYE6 = np.eye(6)
_STALL = 0.98  # an iteration that leaves more than this fraction of the error has stalled


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
    clips to the joint limits, so every iterate (and the result) is within limits.

    compiled=True runs the same algorithm in one numba kernel (ik_kernels.ik_solve: the 6x6 system by
    Cholesky instead of numpy's LU, so the last bits differ; the same inputs give the same bits).
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
        compiled: bool = False,
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
        self.compiled = compiled  # the compiled solver (sessions of format 3 on); False: the numpy one
        self._tip_index = self.chain.link_index[last.child]
        self._joint_links = np.array([self.chain.link_index[j.child] for j in self.chain.joints])
        self._axes = np.array([j.axis for j in self.chain.joints])
        self._revolute = np.array([j.type != "prismatic" for j in self.chain.joints])
        self._all_revolute = bool(self._revolute.all())
        self.kernel_args: tuple = ()  # compiled: ik_kernels.ik_solve's arguments after target and q_start
        if compiled:
            self.kernel_args = self._kernel_args()
            q = self.chain.neutral()  # load the kernel from numba's cache now, not in a live loop's first steps
            self.solve(self.pose(q), q)

    def _kernel_args(self) -> tuple:
        """The compiled solver's tables and settings: FkTable, IkChain, IkSettings (imports numba: only a
        compiled ArmIK builds them)."""
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

    def _jacobian(self, world: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        frames = world[self._joint_links]
        axes = (frames[:, :3, :3] @ self._axes[:, :, None])[:, :, 0]
        lever = tcp[:3, 3] - frames[:, :3, 3]
        jac = np.empty((6, len(axes)))
        ax, ay, az = axes.T
        lx, ly, lz = lever.T
        # revolute: linear part axis x lever (written out: np.cross is slow on small arrays); prismatic: axis
        jac[0], jac[1], jac[2] = ay * lz - az * ly, az * lx - ax * lz, ax * ly - ay * lx
        if not self._all_revolute:
            jac[:3] = np.where(self._revolute, jac[:3], axes.T)
        jac[3:] = (axes * self._revolute[:, None]).T
        return jac

    def solve(self, target: np.ndarray, q_start: np.ndarray) -> IkResult:
        if self.compiled:
            from teleprev.kernels import ik as ik_kernels
            # fresh writeable float64 copies: a read-only array (a decoded message) would make numba compile
            # another signature, seconds in the live loop
            q, converged, iterations, pos_err, rot_err = ik_kernels.ik_solve(
                np.array(target, dtype=np.float64), np.array(q_start, dtype=np.float64), *self.kernel_args)
            return IkResult(q, converged, iterations, pos_err, rot_err)
        result = self._solve(target, q_start, self.max_step)
        if not result.converged and self.retry:
            # A long first step can land a joint on its limit in a local minimum; short steps from the
            # start follow the error down more faithfully (rare, so the common case stays fast).
            retry = self._solve(target, q_start, self.max_step / 8)
            if retry.converged or retry.position_error < result.position_error:
                return retry
        return result

    def _solve(self, target: np.ndarray, q_start: np.ndarray, max_step: float) -> IkResult:
        q = self.chain.clip(np.asarray(q_start, dtype=float))
        eye = _EYE6
        pos_err = rot_err = np.inf
        last = np.inf
        for it in range(self.max_iterations + 1):
            world = self.chain.fk(q).world
            tcp = world[self._tip_index] @ self.tcp
            e_pos = target[:3, 3] - tcp[:3, 3]
            e_rot = rotation_error(target[:3, :3], tcp[:3, :3])
            pos_err, rot_err = float(e_pos @ e_pos) ** 0.5, float(e_rot @ e_rot) ** 0.5
            if pos_err <= self.position_tolerance and rot_err <= self.rotation_tolerance:
                return IkResult(q, True, it, pos_err, rot_err)
            # Stalled (a joint pinned at its limit, an unreachable target): more iterations won't help.
            progress = pos_err / self.position_tolerance + rot_err / self.rotation_tolerance
            if it == self.max_iterations or progress > _STALL * last:
                break
            last = progress
            jac = self._jacobian(world, tcp)
            err = np.concatenate([e_pos, e_rot])
            # Damping grows with the error, so far targets take careful steps near singularities while
            # the last millimetres converge quickly.
            lam2 = self.damping + 1e-2 * float(err @ err)
            dq = jac.T @ np.linalg.solve(jac @ jac.T + lam2 * eye, err)
            # Joints pinned at a limit and pushed further out are taken out of the step, so the others
            # make up for them instead of the solver stalling against the limit.
            pinned = ((q <= self.chain.lower + 1e-9) & (dq < 0)) | ((q >= self.chain.upper - 1e-9) & (dq > 0))
            if pinned.any():
                free = jac * ~pinned
                dq = free.T @ np.linalg.solve(free @ free.T + lam2 * eye, err)
            biggest = np.max(np.abs(dq))
            if biggest > max_step:
                dq *= max_step / biggest
            q = np.minimum(np.maximum(q + dq, self.chain.lower), self.chain.upper)
        return IkResult(q, False, self.max_iterations, pos_err, rot_err)
