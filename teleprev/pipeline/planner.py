"""Commands sampled at the instant they are sent: the arithmetic of the paced command sender.

A pipeline step makes no commands. It hands the planner its targets (a
TargetUpdate: the arm's IK solution and the hand's corrected joints, each with the velocity the step
estimated from the targets before it) and every accepted mode switch (a ModeUpdate). The planner runs on
the sender's clock (teleprev/live/core/sender.py): at each tick it adopts the updates that have arrived, then
samples the motion at the tick's own instant. A late tick samples further along, so it is never followed
by a catch-up burst, and nothing the session loop does (or fails to do in time) reaches the commands
other than through their targets.

    arm    a jerk-limited profile (ruckig) from the last command's position, velocity and acceleration
           towards the target moved on by its velocity to this instant (at most EXTRAPOLATE_MAX_NS; then
           the target held there, met at rest), sampled at the tick, under joint velocity limits that keep
           the flange within its linear speed cap (teleprev/pipeline/tcp_speed.py: never a clamped sample,
           so acceleration and jerk stay within theirs); a profile whose stop (braking as
           hard as the limits allow from the sampled state) would pass a joint limit is not taken: the
           arm brakes instead, so it never needs holding at a limit
    hand   the acceleration cap towards the target (where the Corrector put it, met moving with it), each
           command segment checked for self-collision with the clearance (Motion's hand step, one tick long)
    stale  a target older than the pipeline's stale limit: that side brakes to rest, then holds
    resume once both sides have targets again after a tick without (stale, missing or invalid input): at
           the engage fraction of the speed caps until the commands meet the targets, as an engage does
           (the session loop sends the session back to preview when the loss lasted too long)
    pause  ticks further apart than RESUME_GAP_NS (the sender starved): the arm stood at the last
           command meanwhile, so the next commands start from rest there, one short step in
    engage at rest, at the engage fraction of the speed caps until the commands meet the targets: the arm
           from its last command while its controller still holds it (the planner commanded it and no
           halt came since: a fault or an e-stop stops the controller, which lets go of it), since a
           servo-mode controller takes a new stream to start where it holds, wherever contact has pushed
           or held the arm meanwhile (0.6 mrad to 0.1 rad in the physics world); else (a first engage,
           after a halt) from the measured state (ModeUpdate "execute"), as the hand always does; while
           braking after a switch to preview, an engage carries on from where the commands are
    preview both sides brake to rest within their limits, then nothing more is sent
    halt   nothing more is sent at once (an e-stop; an actuator that failed: its controller stopped it)

In execute every tick sends both sides, holding where there is nothing to move to, so a controller never
sees a paused stream while engaged. The planner is deterministic: the same updates adopted at the same
ticks give the same commands bit for bit, which is how `teleprev eval` re-runs a session (each tick's
record names the last update it had adopted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from teleprev.kernels.motion import (
    ESTIMATE_BLEND,
    ESTIMATE_GIVEN,
    ESTIMATE_HELD,
    ESTIMATE_NONE,
    ESTIMATE_RAW,
    velocity_estimate,
)
from teleprev.pipeline.derivatives import RESUME_GAP_NS, RESUME_PERIOD_NS
from teleprev.pipeline.frozen import evolve
from teleprev.pipeline.motion import (
    ENGAGED_TOL,
    EXTRAPOLATE_MAX_NS,
    FEEDFORWARD_MAX_GAP_NS,
    RESUME_STEP_S,
    STREAM_START_TICKS,
    Motion,
)
from teleprev.pipeline.trajectory import PLAN_GOAL, JointMotion, float_vector


@dataclass(frozen=True)
class TargetUpdate:
    """One pipeline step's targets for the planner. A side's target is None where its input was unusable
    (missing, stale, invalid): that side brakes."""

    seq: int
    t_ns: int  # the step's log time: its inputs' time
    arm: np.ndarray | None = None  # IK solution
    arm_v: np.ndarray | None = None  # its velocity, estimated from the wrist samples before (None: none)
    arm_ns: int = 0  # the stamp of the wrist sample it solves: extrapolated from there
    hand: np.ndarray | None = None  # the end effector's target (the Corrector's, for a hand)
    hand_v: np.ndarray | None = None


@dataclass(frozen=True)
class ModeUpdate:
    """An accepted mode switch: "execute" (from `arm` / `hand`, the measured state within the limits),
    "preview" (brake to rest, then send nothing) or "halt" (send nothing more, at once)."""

    seq: int
    t_ns: int
    mode: str
    arm: np.ndarray | None = None
    hand: np.ndarray | None = None


@dataclass(frozen=True)
class Tick:
    """What one tick sent: the commands (None: that side sent nothing) at the tick's instant t_ns, the last
    update adopted by then, and flags saying why the commands are as they are."""

    t_ns: int
    seq: int
    arm: np.ndarray | None
    arm_v: np.ndarray | None
    hand: np.ndarray | None
    hand_v: np.ndarray | None
    flags: tuple[str, ...] = ()
    active: bool = True  # the planner still commands after this tick (False: it came to rest in preview)


@dataclass
class _Side:
    """The commands of one side: position, velocity (and acceleration, for the arm's JointMotion)."""

    motion: JointMotion | None = None  # the arm
    q: np.ndarray | None = None  # the hand (or gripper / vacuum)
    v: np.ndarray | None = None


@dataclass
class PlannerState:
    mode: str = "preview"  # "preview" | "execute"
    active: bool = False  # commanding (executing, or braking after a switch to preview)
    engaging: bool = False
    input_lost: bool = False  # a tick in execute had no target for a side: the next full one resumes slowly
    last_ns: int | None = None  # the last tick that sent
    dt_before: float = 0.0  # the interval before it (the hand cap's span)
    stream_ticks: int = 0  # ticks sent since the arm's stream started (an engage from rest, a pause)
    arm: _Side = field(default_factory=_Side)
    hand: _Side = field(default_factory=_Side)
    target: TargetUpdate | None = None  # the latest adopted
    seq: int = 0  # the last update adopted


class CommandPlanner:
    """Samples the commands at each tick from the adopted updates (see the module docstring)."""

    resumes_slowly = True  # after input loss, at the engage fraction (older sessions: False, older_formats)
    engages_from_held = True  # the arm engages from the command its controller holds (formats <= 6: False)
    caps_tcp_speed = True  # the arm's speed fraction keeps the flange within its cap (formats <= 9: False)

    def __init__(self, motion: Motion, effector_guard, engage_speed_frac: float, stale_ns: int):
        self.motion = motion
        self.arm = motion.arm  # ArmGenerator
        self.hand = motion.hand  # HandLimiter, or None (a switch: its guard's step)
        self.effector_guard = effector_guard
        self.engage_speed_frac = engage_speed_frac
        self.stale_ns = stale_ns
        self.state = PlannerState()

    @classmethod
    def for_pipeline(cls, pipeline) -> CommandPlanner:
        """The planner of a pipeline: its Motion's limits, its end effector's guard, its config; the class
        its session format's pipeline names (`planner`: an older format's re-run), else this one."""
        cfg = pipeline.cfg
        planner = getattr(pipeline, "planner", None) or cls
        return planner(pipeline.motion, pipeline.effector.guard, cfg.engage_speed_frac, int(cfg.stale_ms * 1e6))

    @property
    def active(self) -> bool:
        return self.state.active

    def adopt(self, update: TargetUpdate | ModeUpdate) -> None:
        s = self.state
        s.seq = update.seq
        if isinstance(update, TargetUpdate):
            s.target = update
        elif update.mode == "halt":
            self.state = PlannerState(seq=s.seq, target=s.target)
        elif update.mode == "preview":
            s.mode, s.engaging = "preview", False
        elif update.mode == "execute":
            if s.mode == "execute":
                return
            s.mode, s.engaging, s.input_lost = "execute", True, False
            if not s.active:  # from rest (braking: carry on from the commands)
                s.arm = _Side(motion=JointMotion.rest(self._engage_arm(np.asarray(update.arm, dtype=float))))
                s.hand = _Side(q=np.asarray(update.hand, dtype=float), v=np.zeros(len(update.hand)))
                # A controller (and the audit) takes a stream to have stood at its first command one cycle
                # before it: the hand's cap spans that cycle and the second command's step.
                s.active, s.last_ns, s.dt_before = True, None, RESUME_PERIOD_NS / 1e9

    def _engage_arm(self, measured: np.ndarray) -> np.ndarray:
        """Where an engage from rest starts the arm: the last command while the controller holds it (see
        the module docstring), else the measured state."""
        held = self.state.arm.motion  # None before the first engage and after a halt
        if self.engages_from_held and held is not None and held.q.shape == measured.shape:
            return held.q.copy()
        return measured

    def tick(self, t_ns: int) -> Tick | None:
        """The commands at t_ns, or None while the planner sends nothing."""
        s = self.state
        if not s.active:
            return None
        flags: list[str] = []
        if s.last_ns is None:  # the first command of an engage: where the robot is
            s.last_ns, s.stream_ticks = t_ns, 0
            return self._sent(t_ns, flags)
        gap = t_ns - s.last_ns
        if gap <= 0:
            return None
        dt = gap / 1e9
        if gap > RESUME_GAP_NS:
            # No command went out for this long (the sender starved): a servo-mode arm has stood at the last
            # command meanwhile, so carry on from rest there, one short step in (the controller takes the
            # next command as the start of a new stream).
            s.arm.motion = JointMotion.rest(s.arm.motion.q)
            s.hand.v = np.zeros_like(s.hand.v)
            dt, s.dt_before, s.stream_ticks = RESUME_STEP_S, 0.0, 0
            flags.append("commands_resumed")
        executing = s.mode == "execute"
        if not executing:
            flags.append("stopping")
        target = s.target if executing else None
        if target is not None and t_ns - target.t_ns > self.stale_ns:
            flags.append("targets_stale")
            target = None
        if executing and self.resumes_slowly:
            if target is None or target.arm is None or target.hand is None:
                s.input_lost = True
            elif s.input_lost:  # the input is back: from the held commands, at the engage fraction
                s.input_lost, s.engaging = False, True
                flags.append("input_resumed")
        frac = self.engage_speed_frac if s.engaging else 1.0
        s.stream_ticks += 1
        arm_reached = self._arm(target, t_ns, dt, frac, flags)
        hand_reached = self._hand(target, t_ns, dt, frac, flags)
        s.dt_before = dt
        s.last_ns = t_ns
        if s.engaging:
            flags.append("engaging")
            if arm_reached and hand_reached:
                s.engaging = False
        if not executing and self._at_rest():
            s.active = False  # came to rest after a switch to preview: this is the last command
        return self._sent(t_ns, flags)

    def _sent(self, t_ns: int, flags: list[str]) -> Tick:
        s = self.state
        m = s.arm.motion
        return Tick(t_ns, s.seq, m.q, m.v, s.hand.q, s.hand.v, tuple(flags), s.active)

    def _at_rest(self) -> bool:
        s = self.state
        return s.arm.motion.at_rest and not s.hand.v.any()

    # ---- the arm ---------------------------------------------------------------------------------
    def _arm(self, target: TargetUpdate | None, t_ns: int, dt: float, frac: float, flags: list[str]) -> bool:
        """One tick of the arm; whether it meets its target (within the engage tolerance)."""
        side = self.state.arm
        m = side.motion
        if target is None or target.arm is None:
            if not m.at_rest:
                side.motion = self._brake(m, dt, flags)
                if self.state.mode == "execute":
                    flags.append("arm_stopping")
            return True
        goal, estimate, velocity, ahead = target.arm, ESTIMATE_NONE, None, 0.0
        tcp, speeds = self.motion.tcp, None
        if self.caps_tcp_speed and tcp is not None:
            speeds = tcp.joint_speeds(m.q, m.v, frac)
            if speeds is not None:  # the engage fraction is in them
                frac = 1.0
                flags.append("arm_tcp_capped")
        if target.arm_v is not None:
            lead = max(t_ns - target.arm_ns, 0)
            if lead <= EXTRAPOLATE_MAX_NS:  # the moving target, moved on to now, met moving with it
                estimate, velocity, ahead = ESTIMATE_HELD, target.arm_v, lead / 1e9
            else:  # no newer target for a while: where the extrapolation stops, met at rest
                goal = target.arm + target.arm_v * (EXTRAPOLATE_MAX_NS / 1e9)
        plan = self.arm.plan(m, goal, dt, frac, estimate, None, velocity, 0.0, 0.0, ahead, speeds)
        starting = self.state.stream_ticks <= STREAM_START_TICKS  # eased in (Motion.start_jerk_frac)
        out = self.arm.follow(m, plan, dt, ENGAGED_TOL, self.motion.start_jerk_frac if starting else 1.0)
        if out is None:  # ruckig found no profile: brake instead
            side.motion = self._brake(m, dt, flags)
            return False
        following, reached, _, held, close = out
        if held or not self.arm.stops_inside(following):
            # This sample would need more room than is left before a joint limit to brake: brake now,
            # which (by the same test at every tick before) stops inside the limits.
            side.motion = self._brake(m, dt, flags)
            flags.append("arm_limit_braking")
            return bool(np.abs(side.motion.q - plan[PLAN_GOAL]).max() < ENGAGED_TOL)
        side.motion = following
        return bool(reached or close)

    def _brake(self, m: JointMotion, dt: float, flags: list[str]) -> JointMotion:
        """The hardest stop the limits allow, dt on; a joint whose stop would pass its limit is held at it as a
        last resort (never needed while every profile taken stops inside them: flagged "arm_limit_held")."""
        out, held = self.arm.brake(m, dt)
        if held:
            flags.append("arm_limit_held")
        return out

    # ---- the hand --------------------------------------------------------------------------------
    def _hand(self, target: TargetUpdate | None, t_ns: int, dt: float, frac: float, flags: list[str]) -> bool:
        """One tick of the end effector; whether it meets its target (within the engage tolerance)."""
        side = self.state.hand
        goal = None if target is None else target.hand
        if self.hand is None:  # a switch (the vacuum): its guard steps to the target
            if goal is not None:
                side.q = self.effector_guard.step(side.q, goal, dt, frac, target_valid=True)
            return goal is None or bool(np.abs(side.q - goal).max() < ENGAGED_TOL)
        if goal is None and not side.v.any():
            return True
        estimate, goal_v = ESTIMATE_NONE, None
        if goal is not None:
            if target.hand_v is not None:
                # met moving at its velocity, where the Corrector put it: moved on, it could leave the
                # clearance the Corrector kept, and the swept check would brake for it
                estimate, goal_v = ESTIMATE_GIVEN, target.hand_v
        elif self.state.mode == "execute":
            flags.append("hand_stopping")
        side.q, side.v, _ = self.motion.hand_move(side.q, side.v, goal, estimate, None, goal_v, 0.0, dt,
                                                  self.state.dt_before, frac, flags)
        return goal is None or bool(np.abs(side.q - goal).max() < ENGAGED_TOL)


class TargetEstimates:
    """The velocity of a step's targets, estimated from the targets before (smoothed: IK solutions jitter
    by its tolerance from sample to sample), for the planner's feed-forward. Kept in PipelineState (as
    `estimates`), so the step stays a pure function."""

    def __init__(self, feedforward: bool, tau_ns: float):
        self.feedforward = feedforward
        self.tau_ns = tau_ns
        _blend(np.zeros(1), None, np.zeros(1), 1, tau_ns)  # load the kernel from numba's cache now, not in a live step

    def arm(self, est: EstimateState, target: np.ndarray, stamp: int) -> tuple[np.ndarray | None, EstimateState]:
        """(velocity estimate, new state) for an arm target solving the wrist sample stamped `stamp`."""
        if not self.feedforward:
            return None, est
        if stamp == est.arm_ns:  # the same wrist sample as last step: the same estimate
            return est.arm_v, est
        v = _blend(est.arm_q, est.arm_v, target, stamp - est.arm_ns, self.tau_ns)
        return v, evolve(est, arm_ns=stamp, arm_q=target, arm_v=v)

    def hand(self, est: EstimateState, target: np.ndarray, t_ns: int) -> tuple[np.ndarray | None, EstimateState]:
        if not self.feedforward:
            return None, est
        v = _blend(est.hand_q, est.hand_v, target, t_ns - est.hand_ns, self.tau_ns)
        return v, evolve(est, hand_ns=t_ns, hand_q=target, hand_v=v)


@dataclass(frozen=True)
class EstimateState:
    arm_ns: int = -1
    arm_q: np.ndarray | None = None
    arm_v: np.ndarray | None = None
    hand_ns: int = -1
    hand_q: np.ndarray | None = None
    hand_v: np.ndarray | None = None


def _blend(before_q, before_v, q, gap_ns: int, tau_ns: float) -> np.ndarray:
    """(q - before) / gap, blended with the estimate before by exp(-gap / tau); zero without a usable
    target before (none, or further back than FEEDFORWARD_MAX_GAP_NS). The quotient and the blend in one
    kernel call (kernels.motion.velocity_estimate)."""
    q = float_vector(q)
    if before_q is None or not 0 < gap_ns <= FEEDFORWARD_MAX_GAP_NS:
        return np.zeros_like(q)
    if before_v is None:
        return velocity_estimate(q, ESTIMATE_RAW, float_vector(before_q), q, gap_ns / 1e9, 0.0)
    return velocity_estimate(q, ESTIMATE_BLEND, float_vector(before_q), float_vector(before_v), gap_ns / 1e9,
                             math.exp(-gap_ns / tau_ns))
