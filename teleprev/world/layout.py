"""What stands on the table for each task, as rigid bodies with mass and friction, drawn from a seed.

The positions are the sim rig's spots (teleprev/world/places.py, which the kinematic sim's task scripts
read too): metres from the operator's resting wrist in the task frame, mapped into the robot base frame
through `anchor` (the TCP at the arm's home pose), with the same jitter. A layout drawn for the simulated
operator's episode takes the spots its script drew (`task_layout(..., spots=...)`), so the objects stand
where the operator reaches. The robot base stands on the table top
(z = 0). Cups and the bowl are hollow (a floor and a ring of tapered wall plates) so that cups nest and
hold the pour's contents; hang's mug is such a cup with a handle whose hole goes over the peg.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from teleprev.world.places import BOX_YAW, DEFAULT_ANCHOR, MUG_HANDLE, MUG_YAW, PEG_HEIGHT, PEG_YAW, SPOTS, TASKS

# Colours (RGBA 0..1), the sim camera's BGR colours turned around.
_CUP_RGBA = ((0.78, 0.24, 0.16, 1.0), (0.16, 0.47, 0.78, 1.0), (0.24, 0.67, 0.24, 1.0))

Kind = Literal["cup", "box", "sphere", "mug"]


@dataclass(frozen=True)
class Shape:
    """A rigid object's geometry and material.

    cup: size = (bottom radius, top radius, height, wall thickness) (a bowl is a wide, low cup)
    box: size = (x, y, z)
    sphere: size = (radius,)
    mug: a cup's size, and a handle on its +x side whose hole (HANDLE_HOLE, its axis along y) goes over a peg
    """

    kind: Kind
    size: tuple[float, ...]
    mass: float  # kg
    friction: float  # sliding friction coefficient (MuJoCo's first friction value)
    rgba: tuple[float, float, float, float] = (0.6, 0.6, 0.6, 1.0)
    rolling: float = 0.0  # m: rolling friction (resists what rolls or swings about a contact), 0: none


@dataclass(frozen=True)
class Placed:
    """An object of the scene: a free rigid body (it moves under the fingers) or a fixed one (the peg)."""

    name: str
    shape: Shape
    position: tuple[float, float, float]  # of the body frame (the base centre for a cup), robot base frame
    yaw: float = 0.0
    fixed: bool = False
    collides: bool = True  # False: a marker only (pick_place's target), drawn but never touched


@dataclass(frozen=True)
class Layout:
    """One episode's scene: the task, the seed it was drawn from and every object's starting pose."""

    task: str
    seed: int
    anchor: tuple[float, float, float]
    objects: tuple[Placed, ...] = field(default_factory=tuple)

    def object(self, name: str) -> Placed:
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(f"no object {name!r} in the {self.task} layout (has {', '.join(o.name for o in self.objects)})")

    @property
    def free(self) -> tuple[Placed, ...]:
        return tuple(o for o in self.objects if not o.fixed)

    def to_record(self) -> dict:
        """A JSON-ready dict: the task, the seed, the anchor and every object's starting pose."""
        return {"task": self.task, "seed": self.seed, "anchor": list(self.anchor),
                "objects": {o.name: {"position": list(o.position), "yaw": o.yaw} for o in self.objects}}


def layout_from_record(record: dict) -> Layout:
    """The layout a record describes: the task's objects drawn from its seed, at the recorded poses (so a
    recording plays back in the scene it was made in even if the drawing changes later)."""
    try:
        drawn = task_layout(record["task"], int(record["seed"]), tuple(record["anchor"]))
        poses = record["objects"]
        if set(poses) != {o.name for o in drawn.objects}:
            raise ValueError(f"objects {sorted(poses)} are not the {drawn.task} task's "
                             f"({', '.join(o.name for o in drawn.objects)})")
        objects = tuple(replace(o, position=tuple(float(v) for v in poses[o.name]["position"]),
                                yaw=float(poses[o.name]["yaw"])) for o in drawn.objects)
    except (KeyError, TypeError) as exc:
        raise ValueError(f"a world layout record needs task, seed, anchor and objects' poses: {exc!r}") from None
    return replace(drawn, objects=objects)


# hang: a mug's handle, a ring standing out of its wall. The hole (out from the wall, up) takes the 12 mm
# peg with about 1 cm to spare each way, as a kitchen mug's does a mug tree's peg.
HANDLE_HOLE = (0.030, 0.034)
HANDLE_Z = MUG_HANDLE[1]  # the hole's centre above the mug's base
HANDLE_BAR = 0.008  # the ring's bars: their width
HANDLE_DEPTH = 0.014  # and their depth (along the hole's axis)

CUP = Shape("cup", (0.032, 0.042, 0.10, 0.004), 0.05, 0.9)
BOWL = Shape("cup", (0.055, 0.075, 0.06, 0.005), 0.25, 0.9, (0.78, 0.55, 0.27, 1.0))
BALL = Shape("sphere", (0.008,), 0.003, 0.6, (0.9, 0.8, 0.2, 1.0))
MUG = Shape("mug", (0.032, 0.042, 0.10, 0.004), 0.06, 0.9, (0.92, 0.9, 0.85, 1.0))
BOX = Shape("box", (0.10, 0.14, 0.08), 0.30, 0.6, (0.7, 0.55, 0.24, 1.0))
PEG_STAND = Shape("box", (0.03, 0.03, 0.26), 1.0, 0.8, (0.55, 0.35, 0.16, 1.0))
# The peg's rolling friction stops a hung mug swinging (a real handle rubs on its peg; without it the
# mug rocks on the peg's edges for ever). The peg lies along its x, its free end at -x.
PEG = Shape("box", (0.10, 0.012, 0.012), 0.05, 0.8, (0.55, 0.35, 0.16, 1.0), rolling=0.015)
TARGET = Shape("box", (0.10, 0.10, 0.002), 0.01, 0.5, (0.3, 0.8, 0.3, 0.6))
POUR_BALLS = 10


def _coloured(shape: Shape, i: int) -> Shape:
    return replace(shape, rgba=_CUP_RGBA[i])


def _jitter(rng: np.random.Generator, scale: float = 0.02) -> np.ndarray:
    return rng.normal(0.0, scale / 2, 2).clip(-scale, scale)


class _Placer:
    def __init__(self, task: str, anchor: tuple[float, float, float], rng: np.random.Generator,
                 given: dict[str, tuple[float, float, float]]):
        self.task = task
        self.anchor = np.asarray(anchor, dtype=float)
        self.rng = rng
        self.given = given

    def xy(self, name: str) -> np.ndarray:
        """An object's spot (places.SPOTS) in the robot base frame: the given one, else drawn with its jitter."""
        if name in self.given:
            return self.anchor[:2] + np.asarray(self.given[name][:2], dtype=float)
        s = SPOTS[self.task][name]
        return self.anchor[:2] + np.array([s.x, s.y]) + _jitter(self.rng, s.jitter)

    def yaw(self, name: str, drawn) -> float:
        """The given spot's yaw, else `drawn()`."""
        return float(self.given[name][2]) if name in self.given else float(drawn())


def _at(xy: np.ndarray, z: float) -> tuple[float, float, float]:
    return (float(xy[0]), float(xy[1]), float(z))


def _pick_place(p: _Placer) -> tuple[Placed, ...]:
    cup, target = p.xy("cup"), p.xy("target")
    return (Placed("cup", _coloured(CUP, 0), _at(cup, 0.0)),
            Placed("target", TARGET, _at(target, 0.001), fixed=True, collides=False))


def _hang(p: _Placer) -> tuple[Placed, ...]:
    mug, peg = p.xy("mug"), p.xy("peg")
    # The peg turned PEG_YAW, its stand at its far end: the free end points the way the mug comes from.
    along = np.array([np.cos(PEG_YAW), np.sin(PEG_YAW)])
    stand = peg + (PEG.size[0] / 2 + PEG_STAND.size[0] / 2) * along
    return (
        Placed("mug", MUG, _at(mug, 0.0), p.yaw("mug", lambda: MUG_YAW)),
        Placed("peg_stand", PEG_STAND, _at(stand, PEG_STAND.size[2] / 2), PEG_YAW, fixed=True),
        Placed("peg", PEG, _at(peg, PEG_HEIGHT), PEG_YAW, fixed=True),
    )


def _pour(p: _Placer) -> tuple[Placed, ...]:
    cup, bowl = p.xy("cup"), p.xy("bowl")
    objects = [Placed("cup", _coloured(CUP, 1), _at(cup, 0.0)), Placed("bowl", BOWL, _at(bowl, 0.0))]
    # The contents: balls in two rings and a column inside the cup, clear of each other and of its walls.
    r, floor = BALL.size[0], CUP.size[3]
    ring = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    spots = [(0.0, 0.0)] + [(0.017 * np.cos(a), 0.017 * np.sin(a)) for a in ring]
    for i in range(POUR_BALLS):
        dx, dy = spots[i % len(spots)]
        z = floor + r + 0.001 + (2 * r + 0.002) * (i // len(spots))
        objects.append(Placed(f"ball{i + 1}", BALL, (float(cup[0] + dx), float(cup[1] + dy), float(z))))
    return tuple(objects)


def _box_rotation(p: _Placer) -> tuple[Placed, ...]:
    box = p.xy("box")
    return (Placed("box", BOX, _at(box, BOX.size[2] / 2), p.yaw("box", lambda: p.rng.uniform(-BOX_YAW, BOX_YAW))),)


def _cup_stack(p: _Placer) -> tuple[Placed, ...]:
    spots = [p.xy(f"cup{i + 1}") for i in range(3)]
    return tuple(Placed(f"cup{i + 1}", _coloured(CUP, i), _at(xy, 0.0))
                 for i, xy in enumerate(spots))


_LAYOUTS = {"pick_place": _pick_place, "hang": _hang, "pour": _pour, "box_rotation": _box_rotation,
            "cup_stack": _cup_stack}


def task_layout(task: str, seed: int, anchor: tuple[float, float, float] = DEFAULT_ANCHOR,
                spots: dict[str, tuple[float, float, float]] | None = None) -> Layout:
    """The scene of `task` drawn from `seed` (the same seed gives the same layout). `spots` (name -> task-frame
    x, y and yaw, as a sim operator's script drew them) replace the draws of the objects they name."""
    if task not in _LAYOUTS:
        raise ValueError(f"unknown task {task!r} (expected {', '.join(TASKS)})")
    unknown = sorted(set(spots or {}) - set(SPOTS[task]))
    if unknown:
        raise ValueError(f"spots {unknown} are not the {task} task's ({', '.join(SPOTS[task])})")
    rng = np.random.default_rng(seed)
    anchor = tuple(float(v) for v in anchor)
    return Layout(task, int(seed), anchor, _LAYOUTS[task](_Placer(task, anchor, rng, dict(spots or {}))))
