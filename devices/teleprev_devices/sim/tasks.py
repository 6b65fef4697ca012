"""The five tasks of the paper as scripts of phases, drawn afresh for every repetition.

Coordinates are the task frame: metres from the operator's resting right wrist, x forward, y left,
z up; the table top is TABLE_Z below the resting wrist. Wrist orientation is roll/pitch/yaw about the
world x, y, z axes applied to the resting orientation (palm facing left, thumb up, fingers forward and
20 degrees down). A phase moves the wrist and/or the hand to a target by its end (min-jerk, inside a
window of the phase); None holds. Each repetition draws its own object layout, speed, grasp tightness
and angles from the episode's random generator; see devices/sim/operator.py for the phase lists.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from teleprev.devices import world_places
from teleprev_devices.sim import grasps

TABLE_Z = world_places.TABLE_Z
TASKS = world_places.TASKS

# Colours are BGR (OpenCV).
CUP_COLOURS = ((40, 60, 200), (200, 120, 40), (60, 170, 60))


@dataclass(frozen=True)
class SceneObject:
    """A rigid object in the task frame: a box (size x y z) or a cylinder (radius, height), centre and yaw."""

    name: str
    kind: str
    size: tuple[float, ...]
    centre: tuple[float, float, float]
    yaw: float = 0.0
    colour: tuple[int, int, int] = (160, 160, 160)
    graspable: bool = True


@dataclass(frozen=True)
class Phase:
    name: str
    duration: float
    position: np.ndarray | None = None  # wrist position target (task frame)
    rpy: np.ndarray | None = None  # wrist orientation target
    hand: np.ndarray | None = None  # (30,) finger angles target, see grasps.py
    wrist_window: tuple[float, float] = (0.0, 1.0)  # part of the phase in which the wrist moves
    hand_window: tuple[float, float] = (0.0, 1.0)
    # Where the operator, watching, moves the wrist instead of `position`: aim(seen, wrist, position) with
    # `seen` the objects' and the robot hand's task-frame (x, y, z, yaw) as the phase begins (see Aim)
    aim: Callable[[dict, np.ndarray, np.ndarray | None], np.ndarray] | None = None


@dataclass(frozen=True)
class Script:
    task: str
    phases: tuple[Phase, ...]
    objects: tuple[SceneObject, ...] = field(default_factory=tuple)
    spots: dict[str, tuple[float, float, float]] = field(default_factory=dict)  # name -> x, y, yaw as drawn


def _v(*xs: float) -> np.ndarray:
    return np.array(xs, dtype=float)


def _spot(b: _Builder, task: str, name: str) -> np.ndarray:
    """An object's place (world_places.SPOTS) with this repetition's jitter."""
    s = world_places.spot(task, name)
    return _v(s.x, s.y, 0) + b.jitter(s.jitter)


def _spots(**xy_yaw) -> dict[str, tuple[float, float, float]]:
    """The spots a script drew, for the physics world's layout: name=(xy, yaw)."""
    return {name: (float(xy[0]), float(xy[1]), float(yaw)) for name, (xy, yaw) in xy_yaw.items()}


class _Builder:
    """Collects phases, scaling every duration by the repetition's speed and a little per-phase jitter."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng
        self.speed = rng.uniform(0.85, 1.2)
        self.phases: list[Phase] = []

    def add(self, name, duration, position=None, rpy=None, hand=None, wrist_window=(0.0, 1.0), hand_window=(0.0, 1.0),
            aim=None):
        d = duration * self.speed * self.rng.uniform(0.9, 1.1)
        self.phases.append(Phase(name, d, position, rpy, hand, wrist_window, hand_window, aim))

    def jitter(self, scale: float = 0.02) -> np.ndarray:
        return self.rng.normal(0.0, scale / 2, 3).clip(-scale, scale) * _v(1, 1, 0)


def _rest(b: _Builder, rest_position: np.ndarray) -> None:
    b.add("return", 1.1, rest_position, _v(0, 0, 0), grasps.rest(b.rng.uniform(0, 0.6)), hand_window=(0.0, 0.8))
    b.add("pause", b.rng.uniform(0.8, 2.2))


def _cup(name: str, xy: np.ndarray, colour, height: float = 0.10) -> SceneObject:
    return SceneObject(
        name, "cylinder", (0.04, height), (float(xy[0]), float(xy[1]), TABLE_Z + height / 2), 0.0, colour
    )


# The LEAP Hand closes on a cup from its side (palm left, fingers forward, levelled): the cup's axis lies
# GRASP_ALONG in front of the TCP (palm_lower) along the fingers and GRASP_OUT on the palm's side, where
# the curled fingers wrap it against the palm (the palm's face is 3.4 cm from the TCP, a cup's wall 3.7 cm
# from its axis at grasp height). GRASP_HEIGHT puts the index finger just under a cup's rim and the ring
# finger 1 cm over the table. The hand comes down STANDOFF further out, then moves in sideways: straight
# down onto the grasp point, the open fingers would land on the rim.
GRASP_ALONG = -0.065
GRASP_OUT = 0.075
GRASP_HEIGHT = 0.135
STANDOFF = 0.05
ABOVE = (0.13, 0.16)  # m over the grasp height where the hand comes round: the ring finger clears a rim
LIFTED = 0.01  # m: an object's base this far over the table is in the hand
NEST_RISE = 0.045  # m from a cup's base to the base of one nested in it (the walls meet 4 cm up, and a little more)
LEVEL = 0.0  # rad of pitch: the resting hand's 20-degree downward tilt kept


def _palm_frame(yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """The fingers' direction and the palm's (task frame, horizontal) for a hand turned `yaw`."""
    return _v(np.cos(yaw), np.sin(yaw), 0), _v(-np.sin(yaw), np.cos(yaw), 0)


def _side_grasp_point(centre: np.ndarray, z: float, yaw: float = 0.0, out: float = 0.0) -> np.ndarray:
    """The wrist (TCP) holding a cup whose axis is at `centre`, `z` up, from `out` further away."""
    along, palm = _palm_frame(yaw)
    p = _v(centre[0], centre[1], 0) - GRASP_ALONG * along - (GRASP_OUT + out) * palm
    return _v(p[0], p[1], z)


def _hand_to(obj: str, offset: np.ndarray):
    """Aim: the wrist to the object where it is seen, plus `offset` (the robot's hand follows the wrist)."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        return _v(*seen[obj][:3]) + offset
    return aim


def _carry(obj: str, goal, base: float | None = None):
    """Aim: move what the hand holds so that the object (as seen) comes over `goal` (task-frame xy, or the
    name of an object seen), its base `base` up (None: the planned height)."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        o = _v(*seen[obj][:3])
        out = np.array(planned if planned is not None else wrist, dtype=float)
        if o[2] < TABLE_Z + LIFTED:  # not in the hand: nothing to carry, the plan goes on
            return out
        g = _v(*seen[goal][:2]) if isinstance(goal, str) else np.asarray(goal, dtype=float)[:2]
        out[:2] = wrist[:2] + g - o[:2]
        if base is not None:  # above the table, or above the goal object's base
            floor = seen[goal][2] if isinstance(goal, str) else TABLE_Z
            out[2] = wrist[2] + (floor + base - o[2])
        return out
    return aim


# pour: the wrist over the bowl at POUR_OVER from its centre, so that rolled ~115 degrees about the
# fingers (the TCP the pivot) the cup, held GRASP_ALONG / GRASP_OUT from the TCP and 8.5 cm below it,
# swings over to point its mouth down into the bowl: the mouth comes to about (-0.065, -0.065) from the TCP.
POUR_OVER = _v(0.065, 0.045, 0)


def _pour_over(bowl: str, cup: str):
    """Aim: the wrist to POUR_OVER from the bowl as seen, corrected by how far the held cup sits from where
    a grasp puts it (seen against the robot's hand)."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        out = np.array(planned if planned is not None else wrist, dtype=float)
        held, hand = _v(*seen[cup][:3]), _v(*seen["hand"][:3])
        if held[2] < TABLE_Z + LIFTED:
            return out
        slip = _v(GRASP_ALONG, GRASP_OUT, 0) - (held - hand)
        out[:2] = (_v(*seen[bowl][:3]) + POUR_OVER + slip)[:2]
        return out
    return aim


def _lift_by(dz: float):
    """Aim: straight up from where the wrist is."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        return wrist + _v(0, 0, dz)
    return aim


def _move_by(offset: np.ndarray):
    """Aim: from where the wrist is, by `offset`."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        return wrist + offset
    return aim


def _pick(b: _Builder, cup: np.ndarray, grasp_z: float, yaw: float, squeeze: float,
          tightness: tuple[float, float] = (0.35, 0.95), name: str = "cup") -> float:
    """Reach, pre-shape, grasp and lift a cup; returns the grasp tightness."""
    c = b.rng.uniform(*tightness)
    high = grasp_z + b.rng.uniform(*ABOVE)
    rpy = _v(0, LEVEL, yaw)
    beside = _side_grasp_point(cup, 0.0, yaw, STANDOFF) - _v(*cup[:2], 0)  # from the cup's base centre
    grip = _side_grasp_point(cup, 0.0, yaw) - _v(*cup[:2], 0)
    # Slower than a free reach near the cup: the arm's acceleration limit (10 rad/s^2) lags a quicker
    # descent by centimetres, and the fingers would land on the table or the rim.
    b.add("reach", 1.4, _side_grasp_point(cup, high, yaw, STANDOFF), rpy, grasps.open_hand(b.rng.uniform(0, 1)),
          hand_window=(0.3, 1.0), aim=_hand_to(name, beside + _v(0, 0, high - TABLE_Z)))
    b.add("approach", 1.0, _side_grasp_point(cup, grasp_z, yaw, STANDOFF),
          aim=_hand_to(name, beside + _v(0, 0, grasp_z - TABLE_Z)))
    b.add("approach", 0.7, _side_grasp_point(cup, grasp_z, yaw), aim=_hand_to(name, grip + _v(0, 0, grasp_z - TABLE_Z)))
    b.add("grasp", 0.5, hand=grasps.power(c))
    b.add(
        "lift",
        0.9,
        _side_grasp_point(cup, grasp_z + b.rng.uniform(0.10, 0.14), yaw),
        hand=grasps.power(min(1.0, c + squeeze)),
    )
    return c


def _place(b: _Builder, target, place_z: float, yaw: float, name: str = "cup", base: float = 0.0,
           goal=None) -> None:
    """Carry the held cup over `target` (its planned xy), set it down with its base `base` above the table
    (watching: over `goal`, an xy or an object's name, as seen) and let go."""
    goal = target if goal is None else goal
    b.add("move", 1.2, _side_grasp_point(target, place_z + b.rng.uniform(0.08, 0.12), yaw), _v(0, LEVEL, yaw),
          aim=_carry(name, goal))
    # Set down a centimetre over its place: lower, the hand (its arm lagging by millimetres) presses the cup
    # into the table, and that squeeze tips it over when the fingers let go.
    b.add("place", 1.0, _side_grasp_point(target, place_z, yaw), aim=_carry(name, goal, base + 0.01))
    # Let go by relaxing the fingers, not opening them wide: straightening fingers sweep along the cup's
    # far side and flick it over. Then straight up, the relaxed fingers sliding off over the rim (moving
    # off sideways, they drag the cup along), and away, the hand opening.
    b.add("release", 0.6, hand=grasps.rest(b.rng.uniform(0, 0.3)))
    _, palm = _palm_frame(yaw)
    b.add("retreat", 0.7, _side_grasp_point(target, place_z + 0.13, yaw), aim=_lift_by(0.13))
    b.add("retreat", 0.5, _side_grasp_point(target, place_z + 0.13, yaw) - 0.05 * palm,
          hand=grasps.open_hand(b.rng.uniform(0, 0.5)), aim=_move_by(-0.05 * palm))


def pick_place(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    cup = _spot(b, "pick_place", "cup")
    target = _spot(b, "pick_place", "target")
    grasp_z = TABLE_Z + GRASP_HEIGHT
    yaw = rng.uniform(-0.25, 0.0)
    _pick(b, cup, grasp_z, yaw, squeeze=rng.uniform(0.25, 0.45))
    _place(b, target, grasp_z, yaw + rng.uniform(0.0, 0.3))
    _rest(b, rest)
    return Script("pick_place", tuple(b.phases), (_cup("cup", cup, CUP_COLOURS[0]),),
                  _spots(cup=(cup, 0.0), target=(target, 0.0)))


def hang(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    spoon = _spot(b, "hang", "spoon")
    peg = _spot(b, "hang", "peg")
    peg_z = TABLE_Z + world_places.PEG_HEIGHT
    down = _v(-1.2, 0.35, 0)  # palm turned down over the spoon, fingers pointing down a little more
    c = rng.uniform(0.5, 0.95)
    b.add("reach", 1.1, spoon + _v(-0.04, -0.01, TABLE_Z + 0.11), down, grasps.open_hand(0.2), hand_window=(0.3, 1.0))
    b.add("approach", 0.6, spoon + _v(-0.04, -0.01, TABLE_Z + 0.05))
    b.add("pinch", 0.5, hand=grasps.pinch(c))
    # Holding a spoon up by its tip takes a firmer pinch than picking it up.
    b.add("lift", 0.8, spoon + _v(-0.04, -0.01, peg_z + 0.05), _v(-0.5, 0.1, 0), grasps.pinch(min(1.0, c + 0.3)))
    b.add("move", 1.2, peg + _v(-0.12, -0.01, peg_z + 0.05))
    b.add("hang", 0.8, peg + _v(-0.04, -0.01, peg_z + 0.04), _v(-0.3, 0.1, 0.15))
    b.add("lower", 0.5, peg + _v(-0.04, -0.01, peg_z + 0.01))
    b.add("release", 0.5, hand=grasps.open_hand(0.2))
    b.add("retreat", 0.6, peg + _v(-0.13, -0.03, peg_z + 0.03), _v(0, 0, 0))
    _rest(b, rest)
    objects = (
        SceneObject(
            "spoon",
            "box",
            (0.16, 0.025, 0.012),
            (spoon[0], spoon[1], TABLE_Z + 0.006),
            world_places.SPOON_YAW,
            (190, 190, 200),
        ),
        SceneObject(
            "peg_stand", "box", (0.03, 0.03, 0.26), (peg[0] + 0.03, peg[1], TABLE_Z + 0.13), 0.0, (40, 90, 140), False
        ),
        SceneObject("peg", "box", (0.07, 0.012, 0.012), (peg[0] - 0.005, peg[1], peg_z), 0.0, (40, 90, 140), False),
    )
    return Script("hang", tuple(b.phases), objects, _spots(spoon=(spoon, world_places.SPOON_YAW), peg=(peg, 0.0)))


def pour(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    cup = _spot(b, "pour", "cup")
    bowl = _spot(b, "pour", "bowl")
    grasp_z = TABLE_Z + GRASP_HEIGHT
    pour_z = TABLE_Z + rng.uniform(0.21, 0.24)
    # Pronation tips the cup's mouth to the left, over the bowl; the xArm's last joint (+-3.11 rad, from
    # -1.57 at home) allows about 90 degrees of it, the shakes shake the contents out.
    tilt = -rng.uniform(1.45, 1.5)
    c = _pick(b, cup, grasp_z, rng.uniform(-0.2, 0.0), squeeze=0.25, tightness=(0.3, 0.6))
    b.add("move", 1.4, bowl + POUR_OVER + _v(0, 0, pour_z), _v(0, 0, 0), aim=_pour_over("bowl", "cup"))
    # The grip tightens while the cup is upside down and shaken, and eases once it is upright again.
    b.add("pour", 1.2, rpy=_v(tilt, 0, 0), hand=grasps.power(min(1.0, c + rng.uniform(0.3, 0.45))))
    b.add("shake", 0.35, rpy=_v(tilt - 0.05, 0, 0))
    b.add("shake", 0.35, rpy=_v(tilt + 0.25, 0, 0))
    b.add("shake", 0.35, rpy=_v(tilt - 0.05, 0, 0))
    b.add("upright", 1.0, rpy=_v(0, 0, 0), hand=grasps.power(c))
    _place(b, cup, grasp_z, 0.0)
    _rest(b, rest)
    objects = (
        _cup("cup", cup, CUP_COLOURS[1]),
        SceneObject("bowl", "cylinder", (0.075, 0.06), (bowl[0], bowl[1], TABLE_Z + 0.03), 0.0, (70, 140, 200), False),
    )
    return Script("pour", tuple(b.phases), objects, _spots(cup=(cup, 0.0), bowl=(bowl, 0.0)))


def box_rotation(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    box = _spot(b, "box_rotation", "box")
    size = (0.10, 0.14, 0.08)
    top = TABLE_Z + size[2]
    down = _v(-1.4, 0.3, 0)  # palm down on the lid
    turn = rng.uniform(1.2, 1.7)
    b.add("reach", 1.1, box + _v(-0.03, 0, top + 0.10), down, grasps.open_hand(0.8), hand_window=(0.3, 1.0))
    b.add("approach", 0.6, box + _v(-0.03, 0, top + 0.035))
    b.add("grip", 0.5, hand=grasps.claw(rng.uniform(0.2, 1.0)))
    b.add("rotate", 1.4, rpy=down + _v(0, 0, turn))
    b.add("release", 0.4, hand=grasps.open_hand(0.3))
    b.add("lift", 0.6, box + _v(-0.03, 0, top + 0.08))
    b.add("unwind", 1.1, box + _v(-0.10, -0.02, top + 0.06), _v(-0.6, 0.1, 0), grasps.rest(0.2))
    # Then square the box up with a flat hand against its near face, fingers pressed together.
    press = rng.uniform(0.2, 0.7)
    b.add("reposition", 1.2, box + _v(-0.13, -0.02, TABLE_Z + 0.05), _v(0, 0, -1.2), grasps.flat(press))
    # Pushing squeezes the fingers together.
    b.add("push", 0.9, box + _v(-0.09, -0.02, TABLE_Z + 0.05), hand=grasps.flat(min(1.0, press + 0.4)))
    b.add("retreat", 0.5, box + _v(-0.16, -0.04, TABLE_Z + 0.10), _v(0, 0, 0), grasps.rest(0.3))
    _rest(b, rest)
    yaw = rng.uniform(-world_places.BOX_YAW, world_places.BOX_YAW)
    objects = (SceneObject("box", "box", size, (box[0], box[1], TABLE_Z + size[2] / 2), yaw, (60, 140, 180)),)
    return Script("box_rotation", tuple(b.phases), objects, _spots(box=(box, yaw)))


def cup_stack(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    cups = [_spot(b, "cup_stack", f"cup{i + 1}") for i in range(3)]
    grasp_z = TABLE_Z + GRASP_HEIGHT
    below = "cup3"
    for level, cup in enumerate(cups[:2], start=1):
        name, yaw = f"cup{level}", rng.uniform(-0.25, 0.0)
        _pick(b, cup, grasp_z, yaw, squeeze=rng.uniform(0.2, 0.4), name=name)
        _place(b, cups[2], grasp_z + NEST_RISE * level, yaw + rng.uniform(0.0, 0.25), name=name, base=NEST_RISE,
               goal=below)
        below = name
    _rest(b, rest)
    objects = tuple(_cup(f"cup{i + 1}", c, CUP_COLOURS[i]) for i, c in enumerate(cups))
    spots = _spots(**{f"cup{i + 1}": (c, 0.0) for i, c in enumerate(cups)})
    return Script("cup_stack", tuple(b.phases), objects, spots)


SCRIPTS = {"pick_place": pick_place, "hang": hang, "pour": pour, "box_rotation": box_rotation, "cup_stack": cup_stack}
