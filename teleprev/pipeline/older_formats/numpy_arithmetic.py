"""The numpy arithmetic that sessions of formats 1 and 2 were computed with.

Its last bits differ from the compiled kernels' of format 3 on (Cholesky against LU, libm's
sin/cos/atan2 against numpy's, float32 sums in a fixed order against OpenBLAS's), so `teleprev eval`
re-runs those sessions with these classes, each the current one with the numpy arithmetic in place of the
kernels:

    NumpyArmIK           damped least squares with numpy's solver          (robot/ik.py: ArmIK)
    NumpyArmRetargeter   the wrist-to-TCP target in numpy                  (retarget/arm.py: ArmRetargeter)
    NumpySweptCheck      every segment by the numpy check                  (pipeline/swept.py: SweptCheck)
    NumpyCorrector       the numpy CPN and CCN                             (noncollision/corrector.py)

(The glove preparation in numpy: step_commands.NumpyPipeline.) Their tests compare them with the
compiled classes within the rounding each kernel documents.
"""

from __future__ import annotations

import numpy as np

from teleprev.noncollision.corrector import Corrector, Prepared
from teleprev.noncollision.mlp import SCORE_BAND
from teleprev.pipeline.older_formats.braking_swept import BrakingSweptCheck
from teleprev.retarget.arm import Anchor, ArmRetargeter
from teleprev.robot.collision_report import CollisionReport
from teleprev.robot.ik import ArmIK, IkResult
from teleprev.transforms import rotation_error

_EYE4 = np.eye(4)
_EYE6 = np.eye(6)
_STALL = 0.98  # an iteration that leaves more than this fraction of the error has stalled (kernels.ik.IK_STALL)


class NumpyArmIK(ArmIK):
    """ArmIK's algorithm with numpy's linear algebra (the 6x6 system by LU)."""

    def solve(self, target: np.ndarray, q_start: np.ndarray) -> IkResult:
        result = self._solve(target, q_start, self.max_step)
        if not result.converged and self.retry:
            # A long first step can land a joint on its limit in a local minimum; short steps from the
            # start follow the error down more faithfully (rare, so the common case stays fast).
            retry = self._solve(target, q_start, self.max_step / 8)
            if retry.converged or retry.position_error < result.position_error:
                return retry
        return result

    def _jacobian(self, world: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        frames = world[self._joint_links]
        axes = (frames[:, :3, :3] @ self._axes[:, :, None])[:, :, 0]
        lever = tcp[:3, 3] - frames[:, :3, 3]
        jac = np.empty((6, len(axes)))
        ax, ay, az = axes.T
        lx, ly, lz = lever.T
        # revolute: linear part axis x lever (written out: np.cross is slow on small arrays); prismatic: axis
        jac[0], jac[1], jac[2] = ay * lz - az * ly, az * lx - ax * lz, ax * ly - ay * lx
        if not self._revolute.all():
            jac[:3] = np.where(self._revolute, jac[:3], axes.T)
        jac[3:] = (axes * self._revolute[:, None]).T
        return jac

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


class NumpyArmRetargeter(ArmRetargeter):
    """The wrist-to-TCP target in numpy, then its IK's solve (a NumpyArmIK for the sessions it re-runs)."""

    def target(self, anchor: Anchor, wrist: np.ndarray) -> tuple[np.ndarray, bool]:
        m = self.m
        t = _EYE4.copy()
        desired = anchor.tcp[:3, 3] + self.scale * (m @ (wrist[:3, 3] - anchor.wrist[:3, 3]))
        t[:3, 3] = np.clip(desired, self.lo, self.hi)
        t[:3, :3] = m @ wrist[:3, :3] @ anchor.wrist[:3, :3].T @ m.T @ anchor.tcp[:3, :3]
        return t, bool((t[:3, 3] != desired).any())

    def solve(self, anchor: Anchor, wrist: np.ndarray, q_start: np.ndarray) -> tuple[IkResult, bool]:
        target, clipped = self.target(anchor, wrist)
        return self.ik.solve(target, q_start), clipped


class NumpySweptCheck(BrakingSweptCheck):
    """Every segment by SweptCheck's numpy check (what it falls back to where the kernels cannot run);
    the whole hand brakes where a command is not free, as in formats up to 5."""

    def _compiled_tables(self) -> None:
        return None


class NumpyCorrector(Corrector):
    """The Corrector with the numpy CPN and CCN."""

    def _load_networks(self) -> None:
        self._nets = None
        self._cpn = self.cpn
        self._one = None  # the single configuration's check alone, as these formats ran it

    def _propose(self, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        proposal = self.ccn(q0)
        return proposal, self._shortest_predicted_free(q0, proposal, None)

    def _prepare_batch(self, q_in: np.ndarray, q0: np.ndarray, pairs: np.ndarray) -> list[Prepared]:
        """The CPN's batched scores decide only where they are further than SCORE_BAND from the threshold
        (batched float32 sums differ from single ones in the last bits), the single network elsewhere: the
        same answers as the rows alone."""
        labels = self.checker.labels_from_pairs(pairs)
        names = self.checker.link_pairs
        out = [Prepared(q_in[i], q0[i], CollisionReport(labels[i], tuple(names[k] for k in np.flatnonzero(pairs[i]))))
               for i in range(len(q0))]
        rows = [i for i, p in enumerate(out) if p.report.colliding]
        if not rows:
            return out
        proposals = [self.ccn(q0[i]) for i in rows]
        steps = 2 ** self.settings.shorten_levels
        fractions = np.arange(1, steps) / steps
        points = np.stack([q0[i] + fractions[:, None] * (p - q0[i]) for i, p in zip(rows, proposals)])
        scores = self.cpn.score(points.reshape(-1, points.shape[-1])).reshape(len(rows), steps - 1)
        for i, proposal, point, score in zip(rows, proposals, points, scores):
            def free(k: int) -> bool:
                s = float(score[k - 1])
                if abs(s - self.cpn.free_below) > SCORE_BAND * (1.0 + abs(s)):
                    return s < self.cpn.free_below
                return self.cpn.predicts_free(point[k - 1])

            shorter = self._shortest_predicted_free(q0[i], proposal, free)
            answer = self._ccn_answer(q_in[i], shorter, proposal, out[i].report)
            out[i] = Prepared(q_in[i], q0[i], out[i].report, proposal, answer)
        return out

    def _shortest_predicted_free(self, q0: np.ndarray, proposal: np.ndarray, free=None) -> np.ndarray | None:
        """The smallest fraction k / 2**shorten_levels of the correction the CPN predicts free, by bisection
        (one CPN call per level, unless `free(k)` answers for the CPN: the batch's scores)."""
        steps = 2 ** self.settings.shorten_levels
        lo, hi = 0, steps  # in units of 1 / 2**levels; hi: the full proposal
        delta = proposal - q0
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if free(mid) if free is not None else self.cpn.predicts_free(q0 + (mid / steps) * delta):
                hi = mid
            else:
                lo = mid
        return None if hi == steps else q0 + (hi / steps) * delta
