"""End effectors as the pipeline sees them: joint names, a target from the hand pose, and a guard.

    leap_hand         16 joints, joint-to-joint retargeting, then the Corrector (never in self-collision)
    parallel_gripper  "gripper": jaw opening in metres, from one finger's flexion
    vacuum            "vacuum": 0 or 1, thresholds with hysteresis on that finger's flexion
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.guard import JointGuard
from teleprev.human.smplx import JOINT_INDEX
from teleprev.retarget.end_effector import GripperMap, VacuumMap
from teleprev.retarget.hand import JointMap, LeapRetargeter
from teleprev.robot.model import RobotModel


@dataclass(frozen=True)
class EffectorTarget:
    retargeted: np.ndarray  # straight from the mapping (clamped to limits)
    target: np.ndarray  # what the guard steps towards: for the hand, collision-free
    action: str  # "untouched" | "ccn" | "fallback"
    colliding_links: tuple[str, ...] = ()
    deviation: float = 0.0


class LeapEffector:
    kind = "leap_hand"

    def __init__(self, hand: RobotModel, corrector, cfg: PipelineConfig, max_dt: float, mapping: dict[str, JointMap] | None = None):
        self.model = hand
        self.names = hand.joint_names
        self.retarget = LeapRetargeter(hand, mapping)
        self.corrector = corrector
        speed = np.minimum(hand.velocity_limit, cfg.hand_speed)
        self.guard = JointGuard(hand.lower, hand.upper, speed, max_dt, checker=corrector.checker)

    def target(self, flexion: np.ndarray, abduction: np.ndarray, previous: np.ndarray | None) -> EffectorTarget:
        q = self.retarget.from_angles(flexion, abduction)
        c = self.corrector.correct(q, previous)
        return EffectorTarget(q, c.q, c.action, tuple(c.colliding_links), float(c.deviation))


class GripperEffector:
    kind = "parallel_gripper"

    def __init__(self, robot: RobotModel, cfg: PipelineConfig, max_dt: float):
        i = robot.joint_index["gripper"]
        self.names = ("gripper",)
        self.joint = JOINT_INDEX[cfg.gripper_joint]
        self.map = GripperMap(float(robot.upper[i]), cfg.gripper_closed_flexion)
        speed = np.array([robot.velocity_limit[i]])
        self.guard = JointGuard(robot.lower[i:i + 1], robot.upper[i:i + 1], speed, max_dt)

    def target(self, flexion: np.ndarray, abduction: np.ndarray, previous: np.ndarray | None) -> EffectorTarget:
        q = np.array([self.map(float(flexion[self.joint]))])
        return EffectorTarget(q, q, "untouched")


class VacuumEffector:
    kind = "vacuum"

    def __init__(self, cfg: PipelineConfig, max_dt: float):
        self.names = ("vacuum",)
        self.joint = JOINT_INDEX[cfg.gripper_joint]
        self.map = VacuumMap(cfg.vacuum_on_flexion, cfg.vacuum_off_flexion)
        self.guard = JointGuard(np.zeros(1), np.ones(1), np.array([np.inf]), max_dt)  # a switch: no speed to cap

    def target(self, flexion: np.ndarray, abduction: np.ndarray, previous: np.ndarray | None) -> EffectorTarget:
        was_on = previous is not None and previous[0] > 0.5
        q = np.array([1.0 if self.map(float(flexion[self.joint]), was_on) else 0.0])
        return EffectorTarget(q, q, "untouched")
