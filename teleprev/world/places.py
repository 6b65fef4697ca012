"""Where things are in the simulated rig, in one place for the kinematic sim devices and the physics world.

Spots are in the task frame: metres from the operator's resting right wrist, x forward, y left. Both
worlds map them into the robot base frame through the anchor (the TCP at the arm's home pose); each
episode draws its own jitter around them (at most `jitter` metres along x and y). This module imports no
physics engine: the sim plugins read it through teleprev.devices.
"""

from __future__ import annotations

from dataclasses import dataclass

TASKS = ("pick_place", "hang", "pour", "box_rotation", "cup_stack")

# The sim arm's default home (joint1..joint6): the palm forward at about (0.40, 0, 0.30) m, fingers 20
# degrees down. The anchor is the LEAP Hand rig's TCP at that pose, in the robot base frame; the table
# top (the robot base's z = 0) lies its height below the resting wrist.
ARM_HOME = (0.0, -0.27, -0.11, 0.0, -0.85, -1.571)
DEFAULT_ANCHOR = (0.405, 0.0, 0.30)
TABLE_Z = -DEFAULT_ANCHOR[2]  # the table top in the task frame
PEG_HEIGHT = 0.18  # hang: the peg's axis above the table top


@dataclass(frozen=True)
class Spot:
    x: float
    y: float
    jitter: float = 0.02  # metres, the largest draw along x and along y


SPOTS: dict[str, dict[str, Spot]] = {
    "pick_place": {"cup": Spot(0.10, -0.10), "target": Spot(0.12, 0.14)},
    "hang": {"mug": Spot(0.10, -0.12), "peg": Spot(0.08, 0.19, 0.01)},
    "pour": {"cup": Spot(0.08, -0.12), "bowl": Spot(0.15, 0.10)},
    "box_rotation": {"box": Spot(0.15, 0.0)},
    "cup_stack": {"cup1": Spot(0.08, -0.16), "cup2": Spot(0.15, -0.02), "cup3": Spot(0.10, 0.15)},
}
BOX_YAW = 0.2  # box_rotation: the box starts turned up to this much (rad) either way
# hang: the mug stands with its handle towards the operator (the hand holds it by its other side), and
# the peg points its free end the other way (-y), so the hand pushes the handle onto it sideways.
MUG_YAW = 3.141592653589793
MUG_HANDLE = (0.0525, 0.055)  # the handle hole's centre: out from the mug's axis, up from its base
PEG_YAW = 1.5707963267948966


def spot(task: str, name: str) -> Spot:
    return SPOTS[task][name]


@dataclass(frozen=True)
class View:
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)


# The sim cameras' viewpoints, in the robot base frame (x forward, z up; the table top at z = 0): the same
# for the kinematic sim camera's renderer and the physics world's cameras.
VIEWS = {
    "front": View((1.55, 0.50, 0.95), (0.30, 0.0, 0.20)),
    "side": View((0.35, -1.45, 0.62), (0.35, 0.0, 0.24)),
    "top": View((0.42, 0.0, 1.45), (0.42, 0.0, 0.0), (1.0, 0.0, 0.0)),
}
