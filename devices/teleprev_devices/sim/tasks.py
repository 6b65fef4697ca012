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

from teleprev.devices import smplx, transforms, world_places
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
    # `seen` the objects' and the robot hand's task-frame (x, y, z, yaw, ...) as the phase begins (see Aim);
    # 3 values (a position), or 6 (a position and the roll, pitch, yaw that replace `rpy`)
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


# pour: the xArm's last joint turns about 88 degrees from where a cup is held upright (it stops at
# -3.11 rad), too little to tip a cup's mouth below the horizontal by a roll alone. A person pours
# with the whole arm: the hand turned towards the bowl (yaw) and its fingers down (pitch) before the
# wrist rolls; from that pose the xArm rolls with its forearm (joint4) and wrist (joint5) as well as
# joint6, the mouth ends about 20 degrees below the horizontal, and every joint keeps about 0.25 rad
# from its limits through the shakes (the arm's IK along the operator's path, over the layouts' jitter).
POUR_RPY = _v(-2.1, 0.9, 1.2)
POUR_Z = 0.22  # m: the wrist over the table as it pours; the mouth comes about as high
CUP_HEIGHT = 0.10
# The hand takes the cup this much lower than a pick does (the ring finger still clear of the table):
# held at GRASP_HEIGHT the fingers close over the rim, and the contents pour onto them.
POUR_GRASP_LOWER = 0.02
# Where the operator aims the mouth, from the bowl's centre: the contents leave by the lower lip and
# the cup turns a little in the fingers as it tips, so that they land about (-1, +2.5) cm from where
# the mouth is aimed (measured over the demos' seeds); aimed this far off, they land round the middle.
POUR_AIM = _v(0.01, -0.025, 0)
EASED = 0.7  # the pour grip once the cup is upright again, on the way back: firm, its fingertips clear of the palm


def _mouth_sweep(rpy: np.ndarray, yaw_now: float, held: np.ndarray) -> np.ndarray:
    """Where the cup's mouth comes, from the wrist, as the wrist turns from level at `yaw_now` to `rpy`:
    the middle of its way from three quarters of the roll (where the contents begin to run out) to the
    whole roll. `held`: the cup's base centre from the wrist, seen now."""
    level = transforms.rpy_to_matrix(0.0, 0.0, yaw_now).T
    ways = [transforms.rpy_to_matrix(s * rpy[0], rpy[1], rpy[2]) @ level @ (held + _v(0, 0, CUP_HEIGHT))
            for s in (0.75, 1.0)]
    return (ways[0] + ways[1]) / 2


def _pour_over(bowl: str, cup: str, rpy: np.ndarray):
    """Aim: the wrist where, turned from its orientation now to `rpy`, it pours the cup's contents into
    the bowl as seen (the held cup seen against the robot's hand: wherever the grasp put it)."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        out = np.array(planned if planned is not None else wrist, dtype=float)
        held, hand = _v(*seen[cup][:3]), _v(*seen["hand"][:3])
        if held[2] < TABLE_Z + LIFTED:
            return out
        out[:2] = (_v(*seen[bowl][:3]) + POUR_AIM - _mouth_sweep(rpy, seen["hand"][3], held - hand))[:2]
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
          tightness: tuple[float, float] = (0.35, 0.95), name: str = "cup", shape=grasps.power) -> float:
    """Reach, pre-shape, grasp (`shape`, one of grasps' shapes) and lift a cup; returns the grasp tightness."""
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
    b.add("grasp", 0.5, hand=shape(c))
    b.add(
        "lift",
        0.9,
        _side_grasp_point(cup, grasp_z + b.rng.uniform(0.10, 0.14), yaw),
        hand=shape(min(1.0, c + squeeze)),
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


# pick_place lets go as a person setting a cup down does, watching it: the carry looked at once more
# over the target (the first look was from where the cup was picked up), the cup lowered until it is
# seen touching the table (carried tilted a few degrees, its base centre is SET_DOWN up when its lowest
# edge touches) and held still a moment, the grip eased (_eased_grip), and only then the hand lifted away
# and opened.
SET_DOWN = 0.004  # m
LOOSE_GRIP = -0.6  # grasps.power's tightness below a grasp: the fingers off the cup's wall, still round it
THUMB_KEPT = 0.5  # of the way from that loose hand's thumb back to where the grip holds it


def _lower_to(obj: str, base: float):
    """Aim: straight down (or up) until the object, as seen, has its base `base` over the table."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        o = _v(*seen[obj][:3])
        if o[2] < TABLE_Z + LIFTED / 2:  # already down (or not in the hand): stay
            return np.array(wrist, dtype=float)
        return wrist + _v(0, 0, TABLE_Z + base - o[2])
    return aim


def _eased_grip(grip: np.ndarray) -> np.ndarray:
    """The hand letting go of a cup standing on the table: the fingers eased to a loose curl, not
    straightened (straightening, they sweep along the cup's far side and flick it over), and the thumb
    only part of the way out (swung out from across the fingers, it knocks the cup's near side)."""
    loose = grasps.power(LOOSE_GRIP)
    thumb = [smplx.JOINT_INDEX[f"thumb{i}"] for i in (1, 2, 3)] + [15 + smplx.JOINT_INDEX["thumb1"]]
    loose[thumb] = THUMB_KEPT * grip[thumb] + (1 - THUMB_KEPT) * loose[thumb]
    return loose


def _set_down(b: _Builder, target, place_z: float, yaw: float, grip: np.ndarray, name: str = "cup") -> None:
    """Carry the cup held with `grip` over `target`, set it down watching it, and let go (see SET_DOWN)."""
    hover = _side_grasp_point(target, place_z + b.rng.uniform(0.08, 0.12), yaw)
    b.add("move", 1.2, hover, _v(0, LEVEL, yaw), aim=_carry(name, target))
    b.add("aim", 0.4, hover, aim=_carry(name, target))
    b.add("place", 1.0, _side_grasp_point(target, place_z, yaw), aim=_carry(name, target, 0.01))
    b.add("set down", 0.5, _side_grasp_point(target, place_z - 0.01, yaw), wrist_window=(0.0, 0.6),
          aim=_lower_to(name, SET_DOWN))
    b.add("release", 0.6, hand=_eased_grip(grip), hand_window=(0.2, 1.0))
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
    squeeze = rng.uniform(0.25, 0.45)
    c = _pick(b, cup, grasp_z, yaw, squeeze=squeeze)
    _set_down(b, target, grasp_z, yaw + rng.uniform(0.0, 0.3), grasps.power(min(1.0, c + squeeze)))
    _rest(b, rest)
    return Script("pick_place", tuple(b.phases), (_cup("cup", cup, CUP_COLOURS[0]),),
                  _spots(cup=(cup, 0.0), target=(target, 0.0)))


# hang: the hand holds the mug as a pick does, its handle towards the operator; the operator brings the
# handle's hole (seen: where the mug's base and yaw put it) in front of the peg's free end, pushes it along
# the peg, lowers its top bar onto it and lets go. The hole leaves about 1 cm round the peg each way.
PEG_LENGTH = 0.10
ON_PEG = 0.035  # m of the peg through the hole when it is let go
HANDLE_DROP = 0.012  # m: lowered from the peg's axis through the hole's centre, its top bar on the peg


def _handle(seen: dict, name: str = "mug") -> np.ndarray:
    """The mug's handle hole as seen: from its base by its axes where the world shows how it leans (a mug
    held in the hand leans and slips, and a lean of 10 degrees moves the hole about 1 cm), else by its yaw."""
    pose = seen[name]
    out, up = world_places.MUG_HANDLE
    if len(pose) >= 10:
        return _v(*pose[:3]) + out * _v(*pose[4:7]) + up * _v(*pose[7:10])
    x, y, z, yaw = pose[:4]
    return _v(x + out * np.cos(yaw), y + out * np.sin(yaw), z + up)


def _handle_to(goal: np.ndarray, name: str = "mug"):
    """Aim: move what the hand holds so that the mug's handle hole (as seen) comes to `goal`."""
    def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
        if seen[name][2] < TABLE_Z + LIFTED:  # not in the hand: the plan goes on
            return np.array(planned if planned is not None else wrist, dtype=float)
        return wrist + goal - _handle(seen, name)
    return aim


def hang(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    mug = _spot(b, "hang", "mug")
    peg = _spot(b, "hang", "peg")
    peg_z = TABLE_Z + world_places.PEG_HEIGHT
    grasp_z = TABLE_Z + GRASP_HEIGHT
    # First over the mug's side, well above it: reaching across from the rest, the fingers (20 degrees
    # down) swept its rim and tipped it over (3 of 8 seeds), the mug being where the hand crosses.
    b.add("reach", 1.0, _side_grasp_point(mug, grasp_z + 0.2, 0.0, STANDOFF), _v(0, LEVEL, 0),
          grasps.open_hand(rng.uniform(0, 1)), hand_window=(0.3, 1.0))
    _pick(b, mug, grasp_z, 0.0, squeeze=rng.uniform(0.25, 0.4), name="mug")
    out, up = world_places.MUG_HANDLE
    yaw = world_places.MUG_YAW
    # The wrist from the handle's hole, the mug held as picked.
    from_hole = _side_grasp_point(mug, grasp_z) - (mug + _v(out * np.cos(yaw), out * np.sin(yaw), TABLE_Z + up))
    tip = peg - _v(0, PEG_LENGTH / 2, 0)
    front = _v(peg[0], tip[1] - 0.03, peg_z)
    on = front + _v(0, 0.03 + ON_PEG, 0)
    b.add("move", 1.6, front + from_hole, _v(0, LEVEL, 0), aim=_handle_to(front))
    b.add("line up", 0.8, front + from_hole, aim=_handle_to(front))
    b.add("thread", 1.2, on + from_hole, aim=_move_by(on - front))
    b.add("lower", 0.6, on + from_hole - _v(0, 0, HANDLE_DROP), aim=_move_by(_v(0, 0, -HANDLE_DROP)))
    b.add("release", 0.6, hand=grasps.open_hand(rng.uniform(0, 0.3)))
    away = _v(0, -0.08, 0.03)
    b.add("retreat", 0.8, on + from_hole + away, aim=_move_by(away))
    _rest(b, rest)
    objects = (
        SceneObject("mug", "cylinder", (0.04, 0.10), (mug[0], mug[1], TABLE_Z + 0.05), yaw, (215, 220, 225)),
        SceneObject("peg_stand", "box", (0.03, 0.03, 0.26), (peg[0], peg[1] + PEG_LENGTH / 2 + 0.015, TABLE_Z + 0.13),
                    0.0, (40, 90, 140), False),
        SceneObject("peg", "box", (0.012, PEG_LENGTH, 0.012), (peg[0], peg[1], peg_z), 0.0, (40, 90, 140), False),
    )
    return Script("hang", tuple(b.phases), objects, _spots(mug=(mug, yaw), peg=(peg, world_places.PEG_YAW)))


def pour(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    cup = _spot(b, "pour", "cup")
    bowl = _spot(b, "pour", "bowl")
    grasp_z = TABLE_Z + GRASP_HEIGHT - POUR_GRASP_LOWER
    pour_z = TABLE_Z + POUR_Z + rng.uniform(-0.01, 0.01)
    rpy = POUR_RPY + _v(rng.uniform(-0.05, 0.05), 0, rng.uniform(-0.05, 0.05))
    yaw = rng.uniform(-0.2, 0.0)
    _pick(b, cup, grasp_z, yaw, squeeze=0.25, tightness=(0.3, 0.6), shape=grasps.pour_grip)
    along, palm = _palm_frame(yaw)
    held = GRASP_ALONG * along + GRASP_OUT * palm + _v(0, 0, TABLE_Z - grasp_z)  # the cup's base from the wrist
    planned = bowl + POUR_AIM - _mouth_sweep(rpy, yaw, held)
    # The grip tightens as the cup tips and stays firm until it is upright again: with the fingers
    # pointing down the cup hangs in them.
    firm = rng.uniform(0.9, 1.0)
    # Over the bowl the hand turns towards it and the fingers point down (the cup tilts, still upright
    # enough to hold its contents), then the wrist rolls the mouth down. Slowly: in this pose the arm's
    # forearm and wrist joints turn about 2.5 rad for each of the moves.
    b.add("move", 4.4, _v(planned[0], planned[1], pour_z), _v(0, rpy[1], rpy[2]), grasps.pour_grip(firm),
          aim=_pour_over("bowl", "cup", rpy))
    b.add("pour", 3.0, rpy=rpy)
    # Held there while the contents run out, with a gentle shake (a hard one shakes the cup out of the
    # hand: upside down it hangs in the fingers).
    b.add("shake", 0.6, rpy=rpy + _v(0.12, 0, 0))
    b.add("shake", 0.6, rpy=rpy + _v(-0.05, 0, 0))
    # Back the way it came, unrolled, then turned back on the way to the cup's place (turned back over
    # the bowl, the wrist would pass its singularity).
    b.add("upright", 3.0, rpy=_v(0, rpy[1], rpy[2]))
    b.add("move", 2.6, _side_grasp_point(cup, grasp_z + 0.12, yaw), _v(0, 0, yaw), grasps.pour_grip(EASED),
          hand_window=(0.5, 1.0))
    _place(b, cup, grasp_z, 0.0)
    _rest(b, rest)
    objects = (
        _cup("cup", cup, CUP_COLOURS[1]),
        SceneObject("bowl", "cylinder", (0.075, 0.06), (bowl[0], bowl[1], TABLE_Z + 0.03), 0.0, (70, 140, 200), False),
    )
    return Script("pour", tuple(b.phases), objects, _spots(cup=(cup, 0.0), bowl=(bowl, 0.0)))


# box_rotation: the hand comes down over the lid palm down, its index and middle fingertips hooked over the
# far edge and its ring finger and thumb hanging down beside the box, and twists about the box's centre:
# the box turns where the fingers catch it, less than the hand does (the fingertips slip over the lid and
# off). So the operator watches how far it has turned and lets go, comes round over it again and twists
# again until it is a quarter turn round (success.py wants 65 degrees; a box looks the same turned half
# way round, so 90 is the middle of what counts). The aims give the wrist's turn as well as its position.
BOX_SIZE = (0.10, 0.14, 0.08)
BOX_DOWN = _v(-1.4, 0.3, 0.0)  # palm down over the lid (the xArm's joint6 near its end: no further)
# The TCP from the lid's centre, in the box's frame, when gripping: 2 cm over the lid puts the hooked
# fingertips just below the far edge (3.5 cm: on the lid, slipping off it: half the twists turn nothing).
BOX_GRIP = _v(-0.04, 0.0, 0.02)
BOX_HOVER = 0.12  # m over the grip where the hand turns to the box before coming down
BOX_AIM = np.pi / 2  # the turn aimed at
BOX_DONE = np.radians(12)  # within this of BOX_AIM the operator stops twisting
BOX_STROKE = np.radians(75)  # the most one twist turns the wrist
BOX_STROKES = 4


class _BoxTwister:
    """The operator's eye on the box: how far it has turned from where it lay (`start`, its yaw as drawn),
    where the hand goes to grip it and how far to twist next. It remembers the wrist's last turn."""

    def __init__(self, start: float):
        self.start = start
        self.yaw = 0.0  # the wrist's yaw (rpy) as last aimed

    def _left(self, seen: dict) -> float:
        """The twist still needed, anticlockwise (0: done)."""
        progress = (seen["box"][3] - self.start) % np.pi  # half a turn round looks the same
        miss = (BOX_AIM - progress) % np.pi
        return 0.0 if miss <= BOX_DONE or miss >= np.pi - BOX_DONE else float(miss)

    def over(self, height: float):
        """Aim: the hand over the box as seen, turned as far as the box has (the nearest way round),
        `height` over the grip; when the box is round, it stays up."""
        def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
            if self._left(seen) == 0.0:
                return np.concatenate([wrist + _v(0, 0, max(0.0, height - 0.05)), BOX_DOWN + _v(0, 0, self.yaw)])
            box = seen["box"]
            self.yaw = float((box[3] - self.start + np.pi / 3) % np.pi - np.pi / 3)
            c, s = np.cos(self.yaw), np.sin(self.yaw)
            d = _v(c * BOX_GRIP[0] - s * BOX_GRIP[1], s * BOX_GRIP[0] + c * BOX_GRIP[1], 0)
            p = _v(box[0], box[1], TABLE_Z + BOX_SIZE[2] + BOX_GRIP[2] + height) + d
            return np.concatenate([p, BOX_DOWN + _v(0, 0, self.yaw)])
        return aim

    def twist(self):
        """Aim: turn the wrist about the box's centre (as seen) by what is left to turn, at most BOX_STROKE."""
        def aim(seen: dict, wrist: np.ndarray, planned: np.ndarray | None) -> np.ndarray:
            turn = min(self._left(seen), BOX_STROKE)
            c, s = np.cos(turn), np.sin(turn)
            box = _v(*seen["box"][:3])
            r = wrist - box
            self.yaw += turn
            return np.concatenate([box + _v(c * r[0] - s * r[1], s * r[0] + c * r[1], r[2]),
                                   BOX_DOWN + _v(0, 0, self.yaw)])
        return aim


def box_rotation(rng: np.random.Generator, rest: np.ndarray) -> Script:
    b = _Builder(rng)
    box = _spot(b, "box_rotation", "box")
    yaw = rng.uniform(-world_places.BOX_YAW, world_places.BOX_YAW)
    eye = _BoxTwister(yaw)
    grip = box + _v(BOX_GRIP[0], BOX_GRIP[1], TABLE_Z + BOX_SIZE[2] + BOX_GRIP[2])  # as planned, blind
    b.add("reach", 1.3, grip + _v(0, 0, BOX_HOVER), BOX_DOWN, grasps.open_hand(0.8), hand_window=(0.3, 1.0),
          aim=eye.over(BOX_HOVER))
    for stroke in range(BOX_STROKES):
        if stroke:
            b.add("align", 1.0, grip + _v(0, 0, BOX_HOVER), BOX_DOWN, aim=eye.over(BOX_HOVER))
        b.add("approach", 1.0, grip, aim=eye.over(0.0))
        b.add("grip", 0.5, hand=grasps.claw(rng.uniform(0.2, 1.0)))
        b.add("twist", 2.2, grip, BOX_DOWN + _v(0, 0, BOX_AIM), aim=eye.twist())
        b.add("release", 0.4, hand=grasps.open_hand(0.3))
        b.add("lift", 0.6, grip + _v(0, 0, 0.09), aim=_lift_by(0.09))
    # Done, the hand clenches on its way back (as operators do between takes): the LEAP Hand's fist is in
    # self-collision, the Corrector's work in this task, up in the air clear of the box.
    b.add("retreat", 1.6, grip + _v(-0.05, 0, 0.15), _v(0, 0, 0), grasps.fist(rng.uniform(0.0, 1.0)),
          hand_window=(0.0, 0.5), aim=_lift_by(0.06))
    _rest(b, rest)
    objects = (SceneObject("box", "box", BOX_SIZE, (box[0], box[1], TABLE_Z + BOX_SIZE[2] / 2), yaw, (60, 140, 180)),)
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
