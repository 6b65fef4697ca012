"""End effectors as the pipeline sees them: joint names, a target from the hand pose, and a guard.

Each carries its row of the end-effector table (teleprev/robot/effectors.py) as `spec`:
    LeapEffector     the LEAP Hand: joint-to-joint retargeting, then the Corrector (never in self-collision)
    GripperEffector  a parallel gripper: jaw opening in metres, from one finger's flexion
    VacuumEffector   a switch: 0 or 1, thresholds with hysteresis on that finger's flexion
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from teleprev.errors import UrdfError
from teleprev.human.smplx import JOINT_INDEX
from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.guard import JointGuard
from teleprev.retarget.end_effector import GripperMap, VacuumMap
from teleprev.retarget.hand import JointMap, LeapRetargeter
from teleprev.robot.effectors import EndEffector
from teleprev.robot.model import RobotModel

if TYPE_CHECKING:  # loading the Corrector's module is left to the rigs that have one
    from teleprev.noncollision.corrector import Corrector


@dataclass(frozen=True)
class EffectorTarget:
    retargeted: np.ndarray  # straight from the mapping (clamped to limits)
    target: np.ndarray  # what the guard steps towards: for the hand, collision-free
    action: str  # "untouched" | "ccn" | "fallback"
    colliding_links: tuple[str, ...] = ()
    deviation: float = 0.0


class Effector(ABC):
    """What the pipeline needs of an end effector."""

    spec: EndEffector  # its row of the end-effector table
    names: tuple[str, ...]  # its joints, in the order of targets and commands
    guard: JointGuard
    corrector: Corrector | None = None  # only a hand that can collide with itself has one

    @abstractmethod
    def target(self, flexion: np.ndarray, abduction: np.ndarray, previous: np.ndarray | None,
               prepared=None) -> EffectorTarget:
        """The target for this hand pose; `previous` is the last target (None before the first);
        `prepared`: this pose's answer from `prepare` (None: computed here)."""

    def prepare(self, flexion: np.ndarray, abduction: np.ndarray, retargeted: np.ndarray | None = None) -> list:
        """The part of `target` that needs no pipeline state, for a batch of poses (N, 15): one entry per
        pose. `retargeted`: the joints the compiled preparation computed with the angles (kernel_table)."""
        return [None] * len(flexion)

    def kernel_table(self) -> np.ndarray | None:
        """The retargeting for the compiled hand preparation to compute with the angles
        (teleprev/kernels/glove.py: rows source, gain, offset, lower, upper); None: the effector
        needs the angles only."""
        return None

    def joint_target(self, q: np.ndarray, previous: np.ndarray | None) -> EffectorTarget:
        """The target for joints asked for directly (a policy's action, not a hand pose): clipped into
        the limits; `retargeted` is the clipped request, `target` what the guard steps towards."""
        clipped = np.clip(np.asarray(q, dtype=float), self.guard.lower, self.guard.upper)
        return EffectorTarget(clipped, clipped, "untouched")


class LeapEffector(Effector):
    def __init__(self, spec: EndEffector, hand: RobotModel, corrector: Corrector, cfg: PipelineConfig, max_dt: float,
                 mapping: dict[str, JointMap] | None = None):
        # the Corrector and the guard work in the URDF's joint order, which the table's must therefore be
        if hand.joint_names != spec.joints:
            raise UrdfError(f"the {spec.name!r} row of the end-effector table names joints {list(spec.joints)}, "
                              f"the URDF has {list(hand.joint_names)}", str(hand.urdf_path))
        self.spec = spec
        self.model = hand
        self.names = spec.joints
        self.retarget = LeapRetargeter(hand, mapping)
        self._table = self.retarget.table()  # the glove kernel retargets with the angles, by this table
        self.corrector = corrector
        speed = np.minimum(hand.velocity_limit, cfg.hand_speed)
        self.guard = JointGuard(hand.lower, hand.upper, speed, max_dt, checker=corrector.checker)

    def prepare(self, flexion: np.ndarray, abduction: np.ndarray, retargeted: np.ndarray | None = None) -> list:
        """Retargeted joints and the Corrector's exact check of them (both element-wise or per row).
        `retargeted`: those joints, where the compiled preparation computed them with the angles."""
        if retargeted is None:
            retargeted = self.retarget.from_angles(flexion, abduction)
        return self.corrector.prepare(retargeted)

    def kernel_table(self) -> np.ndarray | None:
        return self._table

    def target(self, flexion: np.ndarray, abduction: np.ndarray, previous: np.ndarray | None,
               prepared=None) -> EffectorTarget:
        if prepared is None:
            prepared = self.prepare(flexion[None], abduction[None])[0]
        c = self.corrector.correct(prepared.q, previous, prepared)
        return EffectorTarget(prepared.q, c.q, c.action, tuple(c.colliding_links), float(c.deviation))

    def joint_target(self, q: np.ndarray, previous: np.ndarray | None) -> EffectorTarget:
        """Joints asked for directly go through the Corrector as retargeted ones do (it clips them into
        the limits first): the target is never in self-collision."""
        clipped = super().joint_target(q, previous).retargeted
        c = self.corrector.correct(clipped, previous)
        return EffectorTarget(clipped, c.q, c.action, tuple(c.colliding_links), float(c.deviation))


class GripperEffector(Effector):
    def __init__(self, spec: EndEffector, robot: RobotModel, cfg: PipelineConfig, max_dt: float):
        self.spec = spec
        self.names = spec.joints
        i = int(robot.indices(spec.joints)[0])
        self.joint = JOINT_INDEX[cfg.gripper_joint]
        self.map = GripperMap(float(robot.upper[i]), cfg.gripper_closed_flexion)
        speed = np.array([robot.velocity_limit[i]])
        self.guard = JointGuard(robot.lower[i:i + 1], robot.upper[i:i + 1], speed, max_dt)

    def target(self, flexion: np.ndarray, abduction: np.ndarray, previous: np.ndarray | None,
               prepared=None) -> EffectorTarget:
        q = np.array([self.map(float(flexion[self.joint]))])
        return EffectorTarget(q, q, "untouched")


class VacuumEffector(Effector):
    def __init__(self, spec: EndEffector, cfg: PipelineConfig, max_dt: float):
        self.spec = spec
        self.names = spec.joints
        self.joint = JOINT_INDEX[cfg.gripper_joint]
        self.map = VacuumMap(cfg.vacuum_on_flexion, cfg.vacuum_off_flexion)
        self.guard = JointGuard(np.zeros(1), np.ones(1), np.array([np.inf]), max_dt)  # a switch: no speed to cap

    def target(self, flexion: np.ndarray, abduction: np.ndarray, previous: np.ndarray | None,
               prepared=None) -> EffectorTarget:
        was_on = previous is not None and previous[0] > 0.5
        q = np.array([1.0 if self.map(float(flexion[self.joint]), was_on) else 0.0])
        return EffectorTarget(q, q, "untouched")

    def joint_target(self, q: np.ndarray, previous: np.ndarray | None) -> EffectorTarget:
        """A switch: on above one half."""
        on = np.array([1.0 if float(np.asarray(q, dtype=float)[0]) > 0.5 else 0.0])
        return EffectorTarget(on, on, "untouched")
