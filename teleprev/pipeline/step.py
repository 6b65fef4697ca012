"""One pipeline step: human pose in, robot targets out.

    glove hand pose --retarget--> effector joints --Corrector--> collision-free target --+
    suit wrist pose --relative to the anchor--> TCP target --IK--> arm joints ------------+--> TargetUpdate

`Pipeline.step(state, inputs)` is a pure function of its arguments: the same state and inputs give the
same outputs bit for bit, which is what lets `teleprev eval` re-run recorded sessions exactly. Its targets
(with their velocity, estimated from the targets before) go to the command planner as a TargetUpdate; the
paced sender samples the commands from them at the instant it sends (teleprev/pipeline/planner.py).
In preview the planner commands nothing; an accepted switch to execute (`set_mode`, then `mode_update`)
starts from the robot's measured joints. Inputs that are missing, stale, non-finite or implausible give
no target for their side and are flagged; nothing computed from them is sent. (Older session formats
re-run with the classes of teleprev/pipeline/older_formats/.)

`Pipeline.joint_step` is the step for joint targets asked for directly (a policy's action, `teleprev
rollout`): the arm's clipped into its joint limits, the end effector's through the Corrector, then the
same TargetUpdate, so the same gate, planner and limits apply as to the operator's targets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from teleprev.human.smplx import FRAME_TURN, TWIST_NOISE, hand_values
from teleprev.kernels import glove as glove_kernels
from teleprev.messages import JointSample, PoseSample
from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.effectors import Effector
from teleprev.pipeline.frozen import evolve
from teleprev.pipeline.guard import JointGuard
from teleprev.pipeline.motion import FEEDFORWARD_TAU_NS, Motion
from teleprev.pipeline.planner import EstimateState, ModeUpdate, TargetEstimates, TargetUpdate
from teleprev.retarget.arm import Anchor, ArmRetargeter

# Human plausibility limits: beyond these a glove or suit is broken, not bending.
MAX_FLEXION, MIN_FLEXION, MAX_ABDUCTION = 2.7, -1.2, 1.3
MAX_JOINT_ROTATION = 2.9  # rad: no finger joint turns this far (axis-angle beyond it wraps round)
MAX_WRIST_DISTANCE = 3.0  # metres from the suit's origin


@dataclass(frozen=True)
class StepInputs:
    """The latest sample of each input stream at trigger time t_ns (session clock)."""

    t_ns: int
    hand: JointSample | None = None  # SMPL-X hand pose from the glove
    wrist: PoseSample | None = None  # right wrist from the suit
    arm: JointSample | None = None  # measured arm joints
    effector: JointSample | None = None  # measured end-effector joints
    hand_input: HandInput | None = None  # Pipeline.prepare_hands' answer for `hand`, when computed ahead
    action: JointSample | None = None  # joint targets asked for directly (joint_step): Pipeline.action_names


@dataclass(frozen=True)
class HandInput:
    """A glove sample, prepared: the finger angles and the effector's preparation, or the flag saying why
    the sample is unusable ("glove_invalid", "glove_out_of_range")."""

    flag: str = ""
    flexion: np.ndarray | None = None
    abduction: np.ndarray | None = None
    effector: Any = None  # Effector.prepare's answer for these angles


@dataclass(frozen=True)
class PipelineState:
    step: int = 0
    mode: str = "preview"
    anchor: Anchor | None = None
    arm_q: np.ndarray | None = None  # last IK solution: the previewed arm target
    arm_q_before: np.ndarray | None = None  # the one before: with arm_q, a constant-velocity IK warm start
    arm_solved_ns: int = -1  # stamp of the wrist sample arm_q solves, when it converged (else -1)
    effector_q: np.ndarray | None = None  # last effector target (collision-free for a hand)
    estimates: EstimateState | None = None  # the targets' velocity estimates (TargetEstimates)


@dataclass(frozen=True)
class StepResult:
    state: PipelineState
    retargeted: np.ndarray | None = None
    corrected: np.ndarray | None = None
    arm_target: np.ndarray | None = None
    report: dict = field(default_factory=dict)
    update: TargetUpdate | None = None  # the targets for the command planner


class Pipeline:
    """The step: compiled glove preparation, arm IK and Corrector; targets for the command planner, whose
    limits are `motion`'s."""

    # the compiled glove preparation: decode, checks, angles (read flexion first), retargeting
    read_gloves = staticmethod(glove_kernels.prepare_rows)

    def __init__(self, cfg: PipelineConfig, arm: ArmRetargeter, arm_guard: JointGuard, effector: Effector,
                 motion: Motion):
        self.cfg = cfg
        self.motion = motion  # the limits on acceleration and jerk the planner keeps
        self.arm = arm
        self.arm_names = arm.ik.joint_names
        self.arm_guard = arm_guard
        self.effector = effector
        self.effector_names = effector.names
        # joint_step's input: the arm's and the end effector's joints as a dataset's `action` names them
        self.action_names = action_names(self.arm_names, self.effector_names)
        self._stale_ns = int(cfg.stale_ms * 1e6)
        self._last_wrist: tuple = (None, "", None)  # (sample, flag, pose): a cache, the step stays pure
        table = effector.kernel_table()
        self._hand_retargets = table is not None  # the glove kernel computes the effector's joints too
        self._glove = glove_kernels.GloveTable(
            FRAME_TURN, np.array([MAX_JOINT_ROTATION**2, MIN_FLEXION, MAX_FLEXION, MAX_ABDUCTION, TWIST_NOISE]),
            table if table is not None else np.zeros((5, 0)))
        self.read_gloves(np.zeros((1, 45)), *self._glove)  # load it from numba's cache now
        self._estimates = TargetEstimates(cfg.arm_feedforward, FEEDFORWARD_TAU_NS)

    def model_hashes(self) -> dict[str, str] | None:
        """{role: sha256} of the model files the pipeline runs (a session records them, eval compares);
        None when it runs none (an end effector without a Corrector)."""
        corrector = self.effector.corrector
        return None if corrector is None else corrector.model_hashes()

    # ---- inputs --------------------------------------------------------------------------------
    def _fresh(self, sample, device: str, t_ns: int, flags: list[str]) -> bool:
        """Present and not older than the stale limit; else flagged "no_<device>" or "<device>_stale"."""
        if sample is None:
            flags.append(f"no_{device}")
            return False
        if t_ns - sample.stamp_ns > self._stale_ns:
            flags.append(f"{device}_stale")
            return False
        return True

    def prepare_hands(self, samples: list[JointSample]) -> list[HandInput]:
        """What each glove sample gives before any pipeline state: finger angles (or why none) and the
        end effector's state-independent work on them. One sample (the live step) or a session's worth at
        once (eval, ahead of the sequential pass). In compiled code (teleprev/kernels/glove.py): decode,
        checks, angles and (for an effector with a kernel table) the retargeted joints, by one row code for
        one sample and for many, so each sample's bits are the same either way
        (tests/pipeline/test_prepared.py); then the effector's preparation of the rows that passed (the
        Corrector's exact check, for the LEAP Hand)."""
        n = len(samples)
        if n == 1:  # the live step's case
            try:
                rows = np.array(hand_values(samples[0].names, samples[0].positions), dtype=float, ndmin=2)
            except KeyError:
                return [HandInput("glove_invalid")]
        else:
            rows = np.empty((n, 45))
            for i, s in enumerate(samples):
                try:
                    rows[i] = hand_values(s.names, s.positions)
                except KeyError:
                    rows[i] = np.nan  # missing components: glove_invalid, as a non-finite sample
        codes, angles, joints = self.read_gloves(rows, *self._glove)
        if n == 1:
            if codes[0]:
                return [HandInput(glove_kernels.FLAG_NAMES[codes[0]])]
            flexion, abduction = angles[:, :15], angles[:, 15:]
            prepared = self.effector.prepare(flexion, abduction, joints if self._hand_retargets else None)
            return [HandInput("", flexion[0], abduction[0], prepared[0])]
        out = [HandInput(glove_kernels.FLAG_NAMES[c]) if c else None for c in codes.tolist()]
        ok = np.flatnonzero(codes == 0)
        if len(ok):
            flexion, abduction = angles[ok, :15], angles[ok, 15:]
            prepared = self.effector.prepare(flexion, abduction, joints[ok] if self._hand_retargets else None)
            for j, k in enumerate(ok.tolist()):
                out[k] = HandInput("", flexion[j], abduction[j], prepared[j])
        return out

    def _hand(self, inputs: StepInputs, flags: list[str]) -> HandInput | None:
        if not self._fresh(inputs.hand, "glove", inputs.t_ns, flags):
            return None
        hand = inputs.hand_input if inputs.hand_input is not None else self.prepare_hands([inputs.hand])[0]
        if hand.flag:
            flags.append(hand.flag)
            return None
        return hand

    def _wrist(self, inputs: StepInputs, flags: list[str]) -> np.ndarray | None:
        s = inputs.wrist
        if not self._fresh(s, "suit", inputs.t_ns, flags):
            return None
        if self._last_wrist[0] is not s:  # the suit runs at half the glove's rate: most samples come twice
            self._last_wrist = (s, *self._wrist_pose(s))
        _, flag, matrix = self._last_wrist
        if flag:
            flags.append(flag)
        return matrix

    @staticmethod
    def _wrist_pose(s: PoseSample) -> tuple[str, np.ndarray | None]:
        """("", the wrist pose) or (why the sample is unusable, None)."""
        p, q = np.asarray(s.position, dtype=float), np.asarray(s.orientation, dtype=float)
        if not all(map(math.isfinite, p.tolist() + q.tolist())):  # 7 floats: cheaper than np.isfinite
            return "suit_invalid", None
        if float(p @ p) > MAX_WRIST_DISTANCE**2 or abs(float(q @ q) ** 0.5 - 1.0) > 0.1:
            return "suit_out_of_range", None
        return "", s.matrix()

    def measured(self, sample: JointSample | None, names: tuple[str, ...]) -> np.ndarray | None:
        if sample is None:
            return None
        if sample.names == names:
            q = np.asarray(sample.positions, dtype=float)
        else:
            try:
                q = np.array([sample.positions[sample.names.index(n)] for n in names], dtype=float)
            except ValueError:
                return None
        return q if np.isfinite(q).all() else None

    def measured_rows(self, samples: list[JointSample], names: tuple[str, ...]) -> tuple[list[int], np.ndarray]:
        """measured() of many samples at once: the stamps and the values (rows) of those it gives values
        for, in order (eval's measured states: 5,700 in a 30 s session)."""
        if samples and all(s.names == names for s in samples):
            try:
                block = np.array([s.positions for s in samples], dtype=float)
            except ValueError:  # ragged rows
                block = None
            if block is not None and block.shape == (len(samples), len(names)):
                keep = np.isfinite(block).all(axis=1).nonzero()[0]
                return [samples[i].stamp_ns for i in keep.tolist()], block[keep]
        kept = [(s.stamp_ns, q) for s in samples if (q := self.measured(s, names)) is not None]
        return [t for t, _ in kept], np.array([q for _, q in kept], dtype=float).reshape(len(kept), len(names))

    # ---- mode ----------------------------------------------------------------------------------
    def set_mode(self, state: PipelineState, mode: str, inputs: StepInputs) -> tuple[PipelineState, str]:
        """Switch preview/execute (or "estop"); returns the new state and "" or why the switch was refused.
        A switch to preview re-anchors at the next step: the preview starts again from where the robot is."""
        if mode == state.mode and mode != "estop":
            return state, ""
        if mode in ("preview", "estop"):
            return evolve(state, mode="preview", anchor=None, arm_q=None, arm_q_before=None, arm_solved_ns=-1), ""
        if mode != "execute":
            return state, f"unknown mode {mode!r}"
        start = self.engage_start(state, inputs)
        if isinstance(start, str):
            return state, start
        refused = self.invalid_start(start[1])
        if refused:
            return state, refused
        return evolve(state, mode="execute"), ""

    def mode_update(self, mode: str, inputs: StepInputs, seq: int) -> ModeUpdate:
        """What an accepted switch (set_mode's) tells the planner: execute from the measured state, preview,
        or halt (an e-stop, or a failed actuator: nothing more is sent)."""
        if mode == "execute":
            arm, hand = self.measured_start(inputs)
            return ModeUpdate(seq, inputs.t_ns, mode, arm, hand)
        return ModeUpdate(seq, inputs.t_ns, "halt" if mode == "estop" else "preview")

    def measured_start(self, inputs: StepInputs) -> tuple[np.ndarray, np.ndarray] | str:
        """The measured arm and end effector within their limits (where an engage starts), or why there
        are none."""
        arm_q = self.measured(inputs.arm, self.arm_names)
        eff_q = self.measured(inputs.effector, self.effector_names)
        if arm_q is None or eff_q is None:
            return "no measured state from the arm or the end effector"
        return (np.clip(arm_q, self.arm_guard.lower, self.arm_guard.upper),
                np.clip(eff_q, self.effector.guard.lower, self.effector.guard.upper))

    def engage_start(self, state: PipelineState, inputs: StepInputs) -> tuple[np.ndarray, np.ndarray] | str:
        """measured_start, or why an engage cannot start (no measured state, nothing previewed yet).
        `invalid_start` says whether the end effector's may be commanded (its check can be long: the
        callers ask it last)."""
        start = self.measured_start(inputs)
        if isinstance(start, str):
            return start
        if state.arm_q is None or state.effector_q is None:
            return "nothing previewed yet (waiting for glove and suit)"
        return start

    def invalid_start(self, eff_q: np.ndarray) -> str:
        """"" or why the end effector's measured state (within its limits) is no command to start from."""
        if self.effector.guard.valid(eff_q):
            return ""
        return ("the end effector's measured state is not a valid command (in self-collision, or closer than the "
                "clearance margin?)")

    # ---- step ----------------------------------------------------------------------------------
    def step(self, state: PipelineState, inputs: StepInputs) -> StepResult:
        flags: list[str] = []
        report = _new_report(state)

        hand = self._hand(inputs, flags)
        retargeted = corrected = None
        effector_q = state.effector_q
        if hand is not None:
            t = self.effector.target(hand.flexion, hand.abduction, state.effector_q, hand.effector)
            retargeted, corrected, effector_q = t.retargeted, t.target, t.target
            report.update(corrector=t.action, colliding_links=list(t.colliding_links), deviation_rad=t.deviation)

        wrist = self._wrist(inputs, flags)
        anchor, arm_q, arm_q_before, arm_fresh = state.anchor, state.arm_q, state.arm_q_before, False
        solved_ns = state.arm_solved_ns
        if wrist is not None and anchor is None:
            measured_arm = self.measured(inputs.arm, self.arm_names)
            if measured_arm is None:
                flags.append("no_arm_state")
            else:
                anchor = self.arm.anchor(wrist, measured_arm)
        if wrist is not None and anchor is not None and inputs.wrist.stamp_ns == solved_ns and state.anchor is anchor:
            # The suit runs at half the glove's rate: this wrist sample was solved, and converged, last step.
            arm_fresh = True
            report["ik_converged"] = True
        elif wrist is not None and anchor is not None:
            start = arm_q if arm_q is not None else self.measured(inputs.arm, self.arm_names)
            if arm_q is not None and arm_q_before is not None:
                # Tracking a smooth motion: extrapolating the last two solutions usually lands within
                # tolerance, so the solver confirms it with one FK instead of iterating.
                start = 2.0 * arm_q - arm_q_before
            if start is not None:
                ik, clipped = self.arm.solve(anchor, wrist, start)
                arm_q_before, arm_q, arm_fresh = arm_q, ik.q, True
                solved_ns = inputs.wrist.stamp_ns if ik.converged else -1
                report["ik_converged"] = ik.converged
                if not ik.converged:
                    flags.append("ik_not_converged")
                if clipped:
                    flags.append("workspace_clipped")

        new = evolve(state, step=state.step + 1, anchor=anchor, arm_q=arm_q, arm_q_before=arm_q_before,
                      arm_solved_ns=solved_ns, effector_q=effector_q)
        arm_target = arm_q if arm_fresh else None  # the effector's: `corrected` (None without a usable glove)
        new, update = self._update(new, inputs, arm_target, corrected, inputs.wrist.stamp_ns if arm_fresh else 0)
        report["flags"] = flags
        return StepResult(new, retargeted, corrected, arm_target, report, update)

    def joint_step(self, state: PipelineState, inputs: StepInputs) -> StepResult:
        """A step on joint targets asked for directly (`inputs.action`, named as `action_names`) in place
        of the glove and suit: the arm's clipped into its joint limits (flagged "arm_clipped"), the end
        effector's through its `joint_target` (the Corrector, for a hand). Recorded as a glove step is:
        `retargeted` is the end effector's request within its limits, `corrected` the Corrector's answer.
        An action that is stale, lacks a joint or is not finite gives no target (that side brakes)."""
        flags: list[str] = []
        report = _new_report(state)
        q = None
        if self._fresh(inputs.action, "policy", inputs.t_ns, flags):
            q = self.measured(inputs.action, self.action_names)
            if q is None:
                flags.append("policy_invalid")
        arm_target = retargeted = corrected = None
        new = evolve(state, step=state.step + 1)
        if q is not None:
            n = len(self.arm_names)
            arm_target = np.clip(q[:n], self.arm_guard.lower, self.arm_guard.upper)
            if not np.array_equal(arm_target, q[:n]):
                flags.append("arm_clipped")
            t = self.effector.joint_target(q[n:], state.effector_q)
            retargeted, corrected = t.retargeted, t.target
            report.update(corrector=t.action, colliding_links=list(t.colliding_links), deviation_rad=t.deviation)
            new = evolve(new, arm_q=arm_target, arm_q_before=state.arm_q, effector_q=corrected)
        arm_ns = inputs.action.stamp_ns if arm_target is not None else 0
        new, update = self._update(new, inputs, arm_target, corrected, arm_ns)
        report["flags"] = flags
        return StepResult(new, retargeted, corrected, arm_target, report, update)

    def _update(self, new: PipelineState, inputs: StepInputs, arm_target, effector_target,
                arm_ns: int) -> tuple[PipelineState, TargetUpdate | None]:
        """(new state, update) for this step's fresh targets (None where the input was unusable): the
        targets with their velocity estimates, for the planner. `arm_ns`: the stamp of the input the arm
        target solves (the wrist sample's, the action's), extrapolated from there."""
        est = new.estimates if new.estimates is not None else EstimateState()
        arm_v = hand_v = None
        if arm_target is not None:
            arm_v, est = self._estimates.arm(est, arm_target, arm_ns)
        if effector_target is not None:
            hand_v, est = self._estimates.hand(est, effector_target, inputs.t_ns)
        update = TargetUpdate(0, inputs.t_ns, arm_target, arm_v, arm_ns, effector_target, hand_v)
        return evolve(new, estimates=est), update


def action_names(arm: tuple[str, ...], effector: tuple[str, ...]) -> tuple[str, ...]:
    """The joints of joint_step's input (a dataset's `action`), as the export names them: "arm.<joint>",
    then "hand.<joint>"."""
    return tuple(f"arm.{n}" for n in arm) + tuple(f"hand.{n}" for n in effector)


def _new_report(state: PipelineState) -> dict:
    """A step's report before anything is known of its inputs."""
    return {"step": state.step, "mode": state.mode, "corrector": "held", "colliding_links": [], "deviation_rad": 0.0}
