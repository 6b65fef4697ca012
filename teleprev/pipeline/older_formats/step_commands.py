"""Pipelines whose steps made their commands themselves, at the glove's rate (formats 1 to 3).

Up to format 3 a step made its commands (StepCommandsPipeline: kept to the motion limits by StepMotion,
formats 2 and 3; NumpyPipeline without a Motion: the speed caps alone, format 1), and the arm's state
samples braked them between steps when the glove went quiet (idle steps, StepCommandsDriver). The state
those commands need (StepCommandsState) and the commands of each step (StepCommandsResult) extend the
current pipeline's: the current step computes the targets, these classes add the commands.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.human.smplx import angles_from_hand_pose_abduction_first, hand_pose_from_values
from teleprev.messages import JointSample
from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.effectors import Effector
from teleprev.pipeline.frozen import evolve
from teleprev.pipeline.guard import JointGuard
from teleprev.pipeline.motion import Motion
from teleprev.pipeline.older_formats.abduction_first import AbductionFirstPipeline
from teleprev.pipeline.older_formats.step_motion import MotionState, StepMotion
from teleprev.pipeline.step import (
    MAX_ABDUCTION,
    MAX_FLEXION,
    MAX_JOINT_ROTATION,
    MIN_FLEXION,
    HandInput,
    PipelineState,
    StepInputs,
    StepResult,
)
from teleprev.retarget.arm import ArmRetargeter

ENGAGED_TOL = 1e-3  # rad: format 1's engage ramp is over when every command is this close to its target


@dataclass(frozen=True)
class StepCommandsState(PipelineState):
    arm_cmd: np.ndarray | None = None  # the last commands sent (execute mode)
    effector_cmd: np.ndarray | None = None
    cmd_ns: int | None = None
    engaging: bool = False
    motion: MotionState | None = None


@dataclass(frozen=True)
class StepCommandsResult(StepResult):
    arm_command: np.ndarray | None = None  # the step's own commands (None: that side sent nothing)
    effector_command: np.ndarray | None = None


class StepCommandsPipeline(AbductionFirstPipeline):
    """Formats 2 and 3: each step makes its commands (StepMotion.commands), at the glove's rate; the arm's
    state samples brake them between steps (idle steps) when the glove goes quiet. Its states are
    StepCommandsStates; the glove read abduction first."""

    def __init__(self, cfg: PipelineConfig, arm: ArmRetargeter, arm_guard: JointGuard, effector: Effector,
                 motion: Motion | None):
        step_motion = None if motion is None else StepMotion(motion, cfg.arm_feedforward,
                                                             int(cfg.max_command_dt_ms * 1e6))
        super().__init__(cfg, arm, arm_guard, effector, step_motion)

    def set_mode(self, state: StepCommandsState, mode: str, inputs: StepInputs) -> tuple[StepCommandsState, str]:
        return self.motion.set_mode(self, state, mode, inputs)

    def step(self, state: StepCommandsState, inputs: StepInputs) -> StepCommandsResult:
        """The current step's targets, then this step's commands towards them."""
        r = super().step(state, inputs)
        new, arm_cmd, eff_cmd = self._make_commands(state, r.state, inputs, r.arm_target, r.corrected,
                                                    r.report["flags"])
        return StepCommandsResult(new, r.retargeted, r.corrected, r.arm_target, r.report, None, arm_cmd, eff_cmd)

    def _update(self, new: PipelineState, inputs: StepInputs, arm_target, effector_target, arm_ns: int):
        return new, None  # no planner: the step makes the commands itself

    def _make_commands(self, state: StepCommandsState, new: StepCommandsState, inputs: StepInputs, arm_target,
                       effector_target, flags: list[str]):
        """(new state, arm command or None, effector command or None) towards this step's fresh targets."""
        return self.motion.commands(self, state, new, inputs, arm_target, effector_target, flags)

    def idle_step(self, state: StepCommandsState, inputs: StepInputs) -> StepCommandsResult | None:
        """Between trigger samples: a step that only brakes moving commands, when no step came for a while."""
        if self.motion is None or not self.motion.idle_due(state, inputs.t_ns):
            return None
        new, arm_cmd, eff_cmd, report = self.motion.idle(self, state, inputs)
        return StepCommandsResult(new, None, None, None, report, None, arm_cmd, eff_cmd)


class NumpyPipeline(StepCommandsPipeline):
    """The glove preparation in numpy, read abduction first (element-wise array arithmetic: a batch gives
    each row the bits it gets alone); without a Motion (format 1), commands under the speed caps alone."""

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
    def set_mode(self, state: StepCommandsState, mode: str, inputs: StepInputs) -> tuple[StepCommandsState, str]:
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

    def _make_commands(self, state: StepCommandsState, new: StepCommandsState, inputs: StepInputs, arm_target,
                       effector_target, flags: list[str]):
        if self.motion is not None:
            return super()._make_commands(state, new, inputs, arm_target, effector_target, flags)
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
        return new, arm_cmd, eff_cmd
