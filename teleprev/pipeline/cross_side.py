"""The two sides kept apart: a side's new target is held when its motion would bring it into contact with
the other side.

Each side's planner moves its robot from the target it last adopted towards the new one; the guard checks
that motion (the straight segment between the two targets in joint space, at `samples` points and its end)
against the other side standing at the target it last adopted, every link of one robot against every link
of the other (teleprev/robot/cross_collision.py: arm against arm, hand against hand and against arm), with
a clearance. A target that fails is replaced, for the planner, by the side's last adopted target at rest
(velocities zero, so nothing is extrapolated towards the contact): the side holds where it is, and the
step's report says so (flag "cross_side_held", and the link pairs). Only what is commanded is guarded: a
side in preview moves nothing, and its targets pass as they are.

The check is of targets, not of every command between them: the planner's jerk-limited path from one
target to the next stays near the straight segment at these rates (a target every 8 ms), and the clearance
covers the difference. A target is also checked where the arm would come to rest if held there: the
planner tracks a target's velocity, so holding a side brakes it past its last target by that velocity's
braking distance (within the arm's acceleration and jerk limits). Both sides move at once; each is
checked against where the other was last sent, so two sides closing on each other are each held before
they meet. tests/bimanual/test_cross_side.py drives the two hands through each other: without the guard
the commands collide, with it none does.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from teleprev.pipeline.planner import ModeUpdate, TargetUpdate
from teleprev.robot.cross_collision import CrossCollisionChecker

CROSS_SIDE_CLEARANCE_M = 0.01  # kept between the two robots' links


@dataclass(frozen=True)
class SideJoints:
    """Where a side's arm and end-effector joints sit in its robot's configuration."""

    arm: np.ndarray  # indices into the robot's joints
    hand: np.ndarray  # (those the robot has: a vacuum switch has no joint)
    hand_cols: np.ndarray  # which of the end effector's values they are
    neutral: np.ndarray
    arm_acceleration: np.ndarray  # the arm's limits, per joint: how far it runs on when a target is held
    arm_jerk: np.ndarray

    @classmethod
    def of(cls, model, arm_names, hand_names, motion) -> SideJoints:
        """`motion`: the side's pipeline's Motion (its arm generator's limits)."""
        cols = [k for k, n in enumerate(hand_names) if n in model.joint_index]
        return cls(model.indices(arm_names), model.indices([hand_names[k] for k in cols]), np.array(cols, dtype=int),
                   model.neutral(), np.asarray(motion.arm.acceleration), np.asarray(motion.arm.jerk))

    def run_on(self, arm_v: np.ndarray | None) -> np.ndarray:
        """How far each arm joint runs on past a target it reaches moving at arm_v, braking within the limits
        (v|v|/2a, and the jerk's ramp to full deceleration: v a/2j)."""
        if arm_v is None:
            return np.zeros_like(self.arm_acceleration)
        v = np.asarray(arm_v, dtype=float)
        return v * np.abs(v) / (2 * self.arm_acceleration) + v * self.arm_acceleration / (2 * self.arm_jerk)

    def full(self, arm: np.ndarray, hand: np.ndarray) -> np.ndarray:
        q = self.neutral.copy()
        q[self.arm] = arm
        if len(self.hand):
            q[self.hand] = np.asarray(hand)[self.hand_cols]
        return q


class CrossSideGuard:
    def __init__(self, checker: CrossCollisionChecker, joints: dict[str, SideJoints], samples: int = 2):
        """`checker` has the sides' robots in the order of `joints` (left, right)."""
        self.checker = checker
        self.joints = joints
        self.order = tuple(joints)
        self.samples = samples
        self.adopted: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # side -> (arm, hand) its planner last took
        self.held = 0  # targets held

    def _contacts(self, side: str, q: np.ndarray, other_q: np.ndarray) -> list[tuple[str, str]]:
        """(left link, right link) pairs in contact, `side` at q and the other at other_q."""
        return self.checker.contacts(q, other_q) if side == self.order[0] else self.checker.contacts(other_q, q)

    def check(self, side: str, arm: np.ndarray, hand: np.ndarray, arm_v: np.ndarray | None = None
              ) -> list[tuple[str, str]]:
        """The (left link, right link) pairs the motion of `side` to (arm, hand), and on to where the arm stops
        if it arrives moving at arm_v, would bring into contact with the other side where it was last sent."""
        other = next(s for s in self.order if s != side)
        if other not in self.adopted:
            return []
        j = self.joints[side]
        other_q = self.joints[other].full(*self.adopted[other])
        start = j.full(*self.adopted[side]) if side in self.adopted else None
        end = j.full(arm, hand)
        stop = j.full(np.asarray(arm) + j.run_on(arm_v), hand)
        points = [end] if start is None else [start + s * (end - start) for s in
                                              np.linspace(0.0, 1.0, self.samples + 1)[1:]]
        points.append(stop)
        for q in points:
            found = self._contacts(side, q, other_q)
            if found:
                return found
        return []

    def guard(self, side: str, update, executing: bool) -> tuple[object, list[tuple[str, str]]]:
        """The update to pass to `side`'s planner in place of `update`, and the contacts that held it ([]: none)."""
        if isinstance(update, ModeUpdate):
            if update.mode == "execute" and update.arm is not None and update.hand is not None:
                self.adopted[side] = (np.asarray(update.arm), np.asarray(update.hand))
            return update, []
        if not isinstance(update, TargetUpdate) or not executing or side not in self.adopted:
            return update, []
        arm_then, hand_then = self.adopted[side]
        arm = arm_then if update.arm is None else update.arm
        hand = hand_then if update.hand is None else update.hand
        found = self.check(side, arm, hand, update.arm_v if update.arm is not None else None)
        if not found:
            self.adopted[side] = (np.asarray(arm), np.asarray(hand))
            return update, []
        self.held += 1
        hold = replace(update, arm=arm_then, arm_v=np.zeros_like(arm_then), hand=hand_then,
                       hand_v=np.zeros_like(hand_then))
        return hold, found
