"""The Corrector of a mirrored hand: the networks of the hand it mirrors, its own exact check.

urdf/leap_hand_left.urdf is the right LEAP Hand mirrored with its joint axes flipped
(scripts/mirror_leap_hand.py), so the left hand at joint angles q is the mirror image of the right hand at the
same q: the same links touch, at the same depths. The right hand's CPN (which links collide at q) and CCN
(q -> a collision-free q nearby) are therefore the left hand's as they are, with no sign changes on their
inputs or outputs; the exact check that has the last word runs on the left hand's own shapes.
tests/bimanual/test_left_hand.py checks both premises (FK mirrored, collisions equal) and the Corrector's
answers equal on both hands.
"""

from __future__ import annotations

from pathlib import Path

from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import RobotModel, load_robot

MIRRORED_HANDS = {"leap_hand_left": "leap_hand_right"}  # a hand description -> the one it mirrors


def load_corrector(cls, models_dir: Path | None, model: RobotModel, checker: SelfCollisionChecker | None = None):
    """`cls.load(models_dir, model, checker)`, or for a mirrored hand its twin's networks around its own check."""
    twin = MIRRORED_HANDS.get(model.name)
    if twin is None:
        return cls.load(models_dir, model, checker)
    twin_model = load_robot(twin)
    source = cls.load(models_dir, twin_model, SelfCollisionChecker(twin_model))
    checker = checker if checker is not None else SelfCollisionChecker(model)
    if tuple(checker.link_names) != tuple(source.checker.link_names) or model.joint_names != twin_model.joint_names:
        raise ValueError(f"{model.name} does not mirror {twin} link for link and joint for joint")
    return cls(model, checker, source.cpn, source.ccn, source.settings, source.files)
