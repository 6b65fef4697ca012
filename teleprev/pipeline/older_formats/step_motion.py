"""The commands made by each pipeline step (formats 2 and 3), under the motion limits.

    execute, target fresh     arm: jerk-limited generator towards the target; hand: acceleration cap,
                              each command segment checked for self-collision with a clearance margin
    execute, target missing   that side brakes to rest within its limits, then holds (no commands)
    switch to preview         both brake to rest within their limits (flag "stopping"), then nothing is sent
    no pipeline step for a    the driver runs `idle` steps on the arm's state samples, which brake the same
    while (trigger device     way: a servo-mode xArm holds its last target, so stopping the commands
    quiet)                    would be an instant freeze
    e-stop                    nothing more is sent at all: the controller stops the robot itself

The motion state (MotionState) lives in the pipeline's state (StepCommandsState), so the step stays a
pure function. The limits themselves, and the hand's swept check, are the current Motion's
(teleprev/pipeline/motion.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from teleprev.kernels.motion import ESTIMATE_BLEND, ESTIMATE_HELD, ESTIMATE_NONE, ESTIMATE_RAW, ESTIMATE_ZERO
from teleprev.pipeline.derivatives import RESUME_GAP_NS
from teleprev.pipeline.frozen import evolve
from teleprev.pipeline.motion import (
    ENGAGED_TOL,
    EXTRAPOLATE_MAX_NS,
    FEEDFORWARD_MAX_GAP_NS,
    FEEDFORWARD_TAU_NS,
    RESUME_STEP_S,
    Motion,
)
from teleprev.pipeline.trajectory import PLAN_ESTIMATE, PLAN_GOAL, JointMotion


@dataclass(frozen=True)
class MotionState:
    arm: JointMotion | None = None  # the arm commands' position, velocity, acceleration
    hand_v: np.ndarray | None = None  # velocity of the last hand command (None: not limited / at rest)
    dt: float = 0.0  # seconds between the last two commands (0: none yet)
    target_ns: int = -1  # stamp of the wrist sample behind the current arm target
    target_q: np.ndarray | None = None
    target_v: np.ndarray | None = None  # its velocity, from the last two wrist samples
    stopping: bool = False  # braking to rest after a switch to preview
    hand_target: np.ndarray | None = None  # the last hand target, and its smoothed velocity
    hand_target_v: np.ndarray | None = None
    idle: bool = False  # the last command came from an idle step

    @property
    def moving(self) -> bool:
        if self.arm is not None and not self.arm.at_rest:
            return True
        return self.hand_v is not None and bool(self.hand_v.any())  # NaN counts as moving, -0.0 does not


class StepMotion(Motion):
    """Motion's limits, with the commands made at each step: the target velocities estimated by the step
    (feed-forward), and idle steps once no step has come for `idle_after_ns`."""

    def __init__(self, motion: Motion, feedforward: bool, idle_after_ns: int):
        super().__init__(motion.arm, motion.hand, motion.swept)
        self.feedforward = feedforward
        self.idle_after_ns = idle_after_ns
        self.feedforward_tau_ns = FEEDFORWARD_TAU_NS

    # ---- mode ----------------------------------------------------------------------------------
    def set_mode(self, p, state, mode: str, inputs):
        if mode == state.mode and mode != "estop":
            return state, ""
        reset = dict(anchor=None, arm_q=None, arm_q_before=None, arm_solved_ns=-1, engaging=False)
        if mode == "estop":
            # The controller's own immediate stop: teleprev sends nothing more.
            return evolve(state, mode="preview", arm_cmd=None, effector_cmd=None, motion=None, **reset), ""
        if mode == "preview":
            m = state.motion
            if m is None or not m.moving:
                return evolve(state, mode="preview", arm_cmd=None, effector_cmd=None, motion=None, **reset), ""
            return evolve(state, mode="preview", motion=evolve(m, stopping=True), **reset), ""
        if mode != "execute":
            return state, f"unknown mode {mode!r}"
        start = p.engage_start(state, inputs)
        if isinstance(start, str):
            return state, start
        if state.motion is not None and state.arm_cmd is not None:
            # Still braking from the last execute: carry on from where the commands are.
            return evolve(state, mode="execute", motion=evolve(state.motion, stopping=False), engaging=True), ""
        arm_q, eff_q = start
        refused = p.invalid_start(eff_q)
        if refused:
            return state, refused
        m = MotionState(arm=JointMotion.rest(arm_q), hand_v=np.zeros_like(eff_q) if self.hand is not None else None)
        return evolve(state, mode="execute", arm_cmd=arm_q, effector_cmd=eff_q, cmd_ns=inputs.t_ns, engaging=True,
                       motion=m), ""

    # ---- commands ------------------------------------------------------------------------------
    def _arm_estimate(self, m: MotionState, inputs, target: np.ndarray) -> tuple:
        """How this step estimates the arm target's velocity (kernels.ESTIMATE_*): from the last two wrist
        samples, smoothed, and the target moved on to now. Returns (estimate, before, before_v, gap in
        seconds, keep, ahead in seconds): ArmGenerator.plan's arguments."""
        if not self.feedforward:
            return ESTIMATE_NONE, None, None, 0.0, 0.0, 0.0
        stamp = inputs.wrist.stamp_ns
        ahead = min(max(inputs.t_ns - stamp, 0), EXTRAPOLATE_MAX_NS) / 1e9
        if stamp == m.target_ns:
            return ESTIMATE_HELD, None, m.target_v, 0.0, 0.0, ahead
        gap = stamp - m.target_ns
        if m.target_q is None or not 0 < gap <= FEEDFORWARD_MAX_GAP_NS:
            return ESTIMATE_ZERO, None, None, 0.0, 0.0, ahead
        # IK targets jitter by its tolerance from sample to sample: smooth the estimate.
        keep = math.exp(-gap / self.feedforward_tau_ns)
        estimate = ESTIMATE_RAW if m.target_v is None else ESTIMATE_BLEND
        return estimate, m.target_q, m.target_v, gap / 1e9, keep, ahead

    def _arm_track(self, m: MotionState, inputs, target: np.ndarray, dt: float, frac: float, flags: list[str],
                   estimates: dict):
        """The arm's command dt on towards a fresh target, held within the joint limits. Returns (the arm's
        motion, the command, whether it reached the target: within the step or the tolerance); a new
        estimate of the target's velocity goes into `estimates` (MotionState's fields)."""
        estimate, before, before_v, gap, keep, ahead = self._arm_estimate(m, inputs, target)
        plan = self.arm.plan(m.arm, target, dt, frac, estimate, before, before_v, gap, keep, ahead)
        if estimate in (ESTIMATE_ZERO, ESTIMATE_RAW, ESTIMATE_BLEND):  # a new wrist sample: its target, its estimate
            estimates.update(target_ns=inputs.wrist.stamp_ns, target_q=target, target_v=plan[PLAN_ESTIMATE])
        out = self.arm.follow(m.arm, plan, dt, ENGAGED_TOL)
        if out is None:  # ruckig found no profile: a controlled stop instead
            arm = self.arm.stop(m.arm, dt)
            close = float(np.abs(arm.q - plan[PLAN_GOAL]).max()) < ENGAGED_TOL
            return arm, self._limit_held(arm.q, flags), close
        arm, reached, command, held, close = out
        if held:
            flags.append("arm_limit_held")
        return arm, command, reached or close

    def _limit_held(self, q: np.ndarray, flags: list[str]) -> np.ndarray:
        """The generator limits velocity, acceleration and jerk, not position: heading for a limit faster
        than it can stop there (a target that jumped, a stop), its profile passes the limit before coming
        back. The joint limits are hard: the command is held at the limit meanwhile."""
        inside = np.minimum(np.maximum(q, self.arm.lower), self.arm.upper)
        if (inside == q).all():
            return q
        flags.append("arm_limit_held")
        return inside

    def _hand_estimate(self, m: MotionState, target: np.ndarray | None, dt: float) -> tuple:
        """How this step estimates the hand target's velocity (kernels.ESTIMATE_*): from the last two
        targets, smoothed. Returns (estimate, before, before_v, keep): HandLimiter.command's arguments."""
        if target is None or not self.feedforward:
            return ESTIMATE_NONE, None, None, 0.0
        if m.hand_target is None or not 0 < dt <= FEEDFORWARD_MAX_GAP_NS / 1e9:
            return ESTIMATE_ZERO, None, None, 0.0
        keep = math.exp(-dt * 1e9 / self.feedforward_tau_ns)
        return ESTIMATE_RAW if m.hand_target_v is None else ESTIMATE_BLEND, m.hand_target, m.hand_target_v, keep

    def _hand_command(self, m: MotionState, last, v, target, dt: float, frac: float, flags: list[str],
                      estimates: dict):
        """_hand_move with Motion's estimate of the target's velocity: (command, velocity); the target and
        its estimate go into `estimates` (MotionState's fields)."""
        estimate, before, before_v, keep = self._hand_estimate(m, target, dt)
        cmd, cmd_v, target_v = self.hand_move(last, v, target, estimate, before, before_v, keep, dt, m.dt, frac,
                                               flags)
        if estimate != ESTIMATE_NONE:
            estimates.update(hand_target=target, hand_target_v=target_v)
        return cmd, cmd_v

    def commands(self, p, state, new, inputs, arm_target, effector_target, flags):
        """(new state, arm command or None, effector command or None) for one step.

        `arm_target` / `effector_target`: this step's fresh targets, or None where the input was unusable.
        """
        m = state.motion
        executing = state.mode == "execute"
        if m is not None and not executing and m.moving and inputs.t_ns - state.cmd_ns > RESUME_GAP_NS:
            # Braking after a switch to preview, but stalled past the resume gap: the arm stands already.
            return evolve(new, motion=None, arm_cmd=None, effector_cmd=None), None, None
        if m is None or not (executing or m.moving):
            return evolve(new, motion=None) if m is not None else new, None, None
        if not executing:
            arm_target = effector_target = None
            flags.append("stopping")
        dt = (inputs.t_ns - state.cmd_ns) / 1e9
        frac = p.cfg.engage_speed_frac if state.engaging else 1.0
        if inputs.t_ns - state.cmd_ns > RESUME_GAP_NS:
            if m.moving:
                # No command went out for this long (the process stalled): a servo-mode arm has stood at the
                # last command meanwhile, so carry on from rest there, not from where the motion would be.
                m = evolve(m, arm=JointMotion.rest(state.arm_cmd),
                            hand_v=None if m.hand_v is None else np.zeros_like(m.hand_v), dt=0.0)
                flags.append("commands_resumed")
                if not (executing or m.moving):
                    return evolve(new, motion=None, arm_cmd=None, effector_cmd=None, cmd_ns=inputs.t_ns), None, None
            # Moving or not, the next command starts from rest one short step ago, not at the last
            # command's time: after a pause the arm (and sim.arm) take a command as the start of a new stream.
            dt = RESUME_STEP_S

        arm_cmd = None
        arm, arm_reached = m.arm, arm_target is None
        estimates: dict = {}  # the targets' velocity estimates this step makes: fields of the new MotionState
        if arm_target is not None:
            arm, arm_cmd, arm_reached = self._arm_track(m, inputs, arm_target, dt, frac, flags, estimates)
        elif not arm.at_rest:
            arm = self.arm.stop(arm, dt)
            if executing:
                flags.append("arm_stopping")
            arm_cmd = self._limit_held(arm.q, flags)

        eff_cmd, hand_v = None, m.hand_v
        if self.hand is None:
            if effector_target is not None:
                eff_cmd = p.effector.guard.step(state.effector_cmd, effector_target, dt, frac, target_valid=True)
        elif effector_target is not None or hand_v.any():
            if effector_target is None and executing:
                flags.append("hand_stopping")
            eff_cmd, hand_v = self._hand_command(m, state.effector_cmd, hand_v, effector_target, dt, frac, flags,
                                                 estimates)

        if arm_cmd is None and eff_cmd is None:
            return evolve(new, motion=evolve(m, arm=arm, hand_v=hand_v, **estimates)), None, None
        a = arm_cmd if arm_cmd is not None else state.arm_cmd
        e = eff_cmd if eff_cmd is not None else state.effector_cmd
        # The engage ramp is over once the arm's generator meets its target within a step (or is within
        # the tolerance of it) and the hand is within the tolerance of its target.
        engaging = state.engaging and executing and not (
            arm_reached and new.effector_q is not None and np.abs(e - new.effector_q).max() < ENGAGED_TOL
        )
        m = evolve(m, arm=arm, hand_v=hand_v, dt=dt, idle=False, **estimates)
        if not executing and not m.moving:
            # Stopped after a switch to preview: forget the commands, as a switch at rest does.
            return evolve(new, motion=None, arm_cmd=None, effector_cmd=None, cmd_ns=inputs.t_ns), arm_cmd, eff_cmd
        if state.engaging and executing:
            flags.append("engaging")
        return evolve(new, arm_cmd=a, effector_cmd=e, cmd_ns=inputs.t_ns, engaging=engaging, motion=m), arm_cmd, eff_cmd

    # ---- idle ----------------------------------------------------------------------------------
    def idle_due(self, state, t_ns: int) -> bool:
        """No pipeline step for a while, and the commands are still moving: time for an idle step."""
        m = state.motion
        return (m is not None and state.cmd_ns is not None and (m.idle or t_ns - state.cmd_ns > self.idle_after_ns)
                and m.moving)  # the cheap tests first: the driver asks at every arm state sample

    def idle(self, p, state, inputs):
        """A step without new targets (the trigger device went quiet): brake to rest within the limits.
        Returns (new state, arm command, effector command, step report)."""
        flags = ["idle_stop"]
        new = evolve(state, step=state.step + 1)
        new, arm_cmd, eff_cmd = self.commands(p, state, new, inputs, None, None, flags)
        if new.motion is not None:
            new = evolve(new, motion=evolve(new.motion, idle=True))
        report = {"step": state.step, "mode": state.mode, "corrector": "held", "colliding_links": [],
                  "deviation_rad": 0.0, "flags": flags}
        return new, arm_cmd, eff_cmd, report
