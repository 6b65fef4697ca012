"""The arithmetic that computed sessions of formats 1 to 3, kept so that they re-run bit for bit.

Up to format 3 a pipeline step made its commands itself, at the glove's rate (StepCommandsPipeline: the
commands kept to the motion limits by Motion, formats 2 and 3); from format 4 on the paced sender samples
them from the step's targets (teleprev/pipeline/planner.py). Up to format 2 the arithmetic was numpy's,
whose last bits differ from the compiled kernels' of format 3 on (Cholesky against LU, libm's
sin/cos/atan2 against numpy's, float32 sums in a fixed order against OpenBLAS's), so `teleprev eval`
re-runs those sessions with these classes, each the current one with the numpy arithmetic in place of the
kernels:

    NumpyArmIK           damped least squares with numpy's solver          (robot/ik.py: ArmIK)
    NumpyArmRetargeter   the wrist-to-TCP target in numpy                  (retarget/arm.py: ArmRetargeter)
    NumpySweptCheck      every segment by the numpy check                  (pipeline/swept.py: SweptCheck)
    NumpyCorrector       the numpy CPN and CCN                             (noncollision/corrector.py)
    AbductionFirstPipeline  format 4: the glove read abduction first       (pipeline/step.py: Pipeline)
                         (kernels/glove.py: prepare_rows_abduction_first)
    StepCommandsPipeline commands made by each step (formats 2 and 3), the glove read abduction first
    NumpyPipeline        the glove preparation in numpy, and format 1's     (pipeline/step.py: Pipeline)
                         commands: speed caps alone, no motion limits

teleprev/assembly.py chooses them by the session's format; nothing else does. Their tests compare them
with the compiled classes within the rounding each kernel documents.
"""

from __future__ import annotations

import numpy as np

from teleprev.human.smplx import angles_from_hand_pose_abduction_first, hand_pose_from_values
from teleprev.kernels import glove as glove_kernels
from teleprev.messages import JointSample
from teleprev.noncollision.corrector import Corrector, Prepared
from teleprev.noncollision.mlp import SCORE_BAND
from teleprev.pipeline.frozen import evolve
from teleprev.pipeline.step import (ENGAGED_TOL, MAX_ABDUCTION, MAX_FLEXION, MAX_JOINT_ROTATION, MIN_FLEXION, HandInput,
                                    Pipeline, PipelineState, StepInputs, StepResult)
from teleprev.pipeline.swept import SweptCheck
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


class NumpySweptCheck(SweptCheck):
    """Every segment by SweptCheck's numpy check (what it falls back to where the kernels cannot run)."""

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


class AbductionFirstPipeline(Pipeline):
    """Formats up to 4 read the glove abduction first, the twist about the bone taken off first (from
    format 5 on: flexion first, teleprev/human/smplx.py)."""

    read_gloves = staticmethod(glove_kernels.prepare_rows_abduction_first)


class StepCommandsPipeline(AbductionFirstPipeline):
    """Formats 2 and 3: each step makes its commands (Motion.commands), at the glove's rate; the arm's state
    samples brake them between steps (idle steps) when the glove goes quiet."""

    plans_commands = False

    def set_mode(self, state: PipelineState, mode: str, inputs: StepInputs) -> tuple[PipelineState, str]:
        return self.motion.set_mode(self, state, mode, inputs)

    def _outputs(self, state: PipelineState, new: PipelineState, inputs: StepInputs, arm_target, effector_target,
                 flags: list[str]):
        new, arm_cmd, eff_cmd = self.motion.commands(self, state, new, inputs, arm_target, effector_target, flags)
        return new, arm_cmd, eff_cmd, None

    def idle_step(self, state: PipelineState, inputs: StepInputs) -> StepResult | None:
        """Between trigger samples: a step that only brakes moving commands, when no step came for a while."""
        if self.motion is None or not self.motion.idle_due(state, inputs.t_ns):
            return None
        new, arm_cmd, eff_cmd, report = self.motion.idle(self, state, inputs)
        return StepResult(new, None, None, None, arm_cmd, eff_cmd, report)


class NumpyPipeline(StepCommandsPipeline):
    """The glove preparation in numpy (element-wise array arithmetic: a batch gives each row the bits it
    gets alone); without a Motion (format 1), commands under the speed caps alone."""

    def prepare_hands(self, samples: list[JointSample]) -> list[HandInput]:
        n = len(samples)
        if n == 1:
            return [self._prepare_hand(samples[0])]
        out = [HandInput() for _ in range(n)]
        poses = np.zeros((n, 15, 3))
        valid = np.ones(n, dtype=bool)
        for i, s in enumerate(samples):
            try:
                poses[i] = hand_pose_from_values(s.names, s.positions)
            except KeyError:
                out[i], valid[i] = HandInput("glove_invalid"), False
        finite = np.isfinite(poses).all(axis=(1, 2))
        in_range = np.einsum("nij,nij->ni", poses, poses).max(axis=1) <= MAX_JOINT_ROTATION**2
        for i in np.flatnonzero(valid & ~(finite & in_range)):
            out[i] = HandInput("glove_invalid" if not finite[i] else "glove_out_of_range")
        rows = np.flatnonzero(valid & finite & in_range)
        if not len(rows):
            return out
        flexion, abduction = angles_from_hand_pose_abduction_first(poses[rows])
        bent = ((flexion.max(axis=1) > MAX_FLEXION) | (flexion.min(axis=1) < MIN_FLEXION)
                | (abs(abduction).max(axis=1) > MAX_ABDUCTION))
        ok = np.flatnonzero(~bent)
        prepared = self.effector.prepare(flexion[ok], abduction[ok])
        for k in np.flatnonzero(bent):
            out[rows[k]] = HandInput("glove_out_of_range")
        for j, k in enumerate(ok):
            out[rows[k]] = HandInput("", flexion[k], abduction[k], prepared[j])
        return out

    def _prepare_hand(self, s: JointSample) -> HandInput:
        """prepare_hands for one sample, without the batch's bookkeeping (the live step's case)."""
        try:
            pose = hand_pose_from_values(s.names, s.positions)
        except KeyError:
            return HandInput("glove_invalid")
        if not np.isfinite(pose).all():
            return HandInput("glove_invalid")
        if np.einsum("ij,ij->i", pose, pose).max() > MAX_JOINT_ROTATION**2:
            return HandInput("glove_out_of_range")
        flexion, abduction = angles_from_hand_pose_abduction_first(pose)
        if flexion.max() > MAX_FLEXION or flexion.min() < MIN_FLEXION or abs(abduction).max() > MAX_ABDUCTION:
            return HandInput("glove_out_of_range")
        return HandInput("", flexion, abduction, self.effector.prepare(flexion[None], abduction[None])[0])

    # ---- format 1: no motion limits ----------------------------------------------------------------
    def set_mode(self, state: PipelineState, mode: str, inputs: StepInputs) -> tuple[PipelineState, str]:
        if self.motion is not None:
            return super().set_mode(state, mode, inputs)
        if mode == state.mode:
            return state, ""
        if mode == "preview":
            # Re-anchor at the next step: the preview starts again from where the robot is.
            return evolve(state, mode="preview", anchor=None, arm_q=None, arm_q_before=None, arm_solved_ns=-1,
                          arm_cmd=None, effector_cmd=None, engaging=False), ""
        if mode != "execute":
            return state, f"unknown mode {mode!r}"
        start = self.engage_start(state, inputs)
        if isinstance(start, str):
            return state, start
        arm_q, eff_q = start
        refused = self.invalid_start(eff_q)
        if refused:
            return state, refused
        return evolve(state, mode="execute", arm_cmd=arm_q, effector_cmd=eff_q, cmd_ns=inputs.t_ns, engaging=True), ""

    def _outputs(self, state: PipelineState, new: PipelineState, inputs: StepInputs, arm_target, effector_target,
                 flags: list[str]):
        if self.motion is not None:
            return super()._outputs(state, new, inputs, arm_target, effector_target, flags)
        arm_cmd = eff_cmd = None
        if state.mode == "execute":
            arm_q, effector_q = new.arm_q, new.effector_q
            dt = (inputs.t_ns - state.cmd_ns) / 1e9 if state.cmd_ns is not None else 0.0
            frac = self.cfg.engage_speed_frac if state.engaging else 1.0
            if arm_target is not None:
                arm_cmd = self.arm_guard.step(state.arm_cmd, arm_q, dt, frac)
            if effector_target is not None:
                eff_cmd = self.effector.guard.step(state.effector_cmd, effector_q, dt, frac, target_valid=True)
            if arm_cmd is not None or eff_cmd is not None:
                a = arm_cmd if arm_cmd is not None else state.arm_cmd
                e = eff_cmd if eff_cmd is not None else state.effector_cmd
                engaging = state.engaging and not (
                    np.max(np.abs(a - arm_q)) < ENGAGED_TOL and np.max(np.abs(e - effector_q)) < ENGAGED_TOL
                )
                new = evolve(new, arm_cmd=a, effector_cmd=e, cmd_ns=inputs.t_ns, engaging=engaging)
            if state.engaging:
                flags.append("engaging")
        return new, arm_cmd, eff_cmd, None
