"""Each task's success, read from the physics state: the one place where "done" is defined.

A task succeeds when its goal holds in every world state of the last REST_S seconds, with every object
let go (no contact with the robot) and at rest (slower than REST_SPEED and REST_SPIN). The goals:

    pick_place    the cup stands upright on the table, its axis within 4 cm of the target's centre
    hang          the peg passes through the mug's handle and the mug hangs from it clear of the table
    pour          at least 8 of the 10 balls lie inside the bowl
    box_rotation  the box lies flat, turned at least 65 degrees about the vertical from where it started
    cup_stack     the three cups stand nested in one upright stack on the table

`judge(layout, states)` gives an Outcome with the reason in words, e.g. "cup 1.2 cm from the target's
centre (needs <= 4), tilted 1 deg (needs <= 10), on the table; let go and at rest for 0.5 s".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from teleprev.world.build import mug_handle_hole
from teleprev.world.layout import HANDLE_BAR, HANDLE_HOLE, POUR_BALLS, Layout
from teleprev.world.world import ObjectState, WorldState

REST_S = 0.5
REST_SPEED = 0.01  # m/s
REST_SPIN = 0.3  # rad/s
ON_TABLE = 0.01  # m: a base this close to the table top stands on it

PLACE_RADIUS = 0.04
UPRIGHT_DEG = 10.0
HANG_CLEARANCE = 0.01
POUR_NEEDED = math.ceil(0.8 * POUR_BALLS)
TURN_DEG = 65.0
STACK_OFFSET = 0.015  # m between the axes of nested cups
STACK_RISE = (0.005, 0.07)  # m from one cup's base to the next one's above it


@dataclass(frozen=True)
class Goal:
    held: bool
    reason: str


@dataclass(frozen=True)
class Outcome:
    task: str
    success: bool
    reason: str
    time_ns: int  # the last state judged

    @property
    def mark(self) -> str:
        """As the operator marks an episode (y / f)."""
        return "success" if self.success else "failure"


def _tilt_deg(o: ObjectState) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(o.rotation[2, 2])))))


def _xy_distance(a, b) -> float:
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))


def _pick_place(layout: Layout, s: WorldState) -> Goal:
    cup, target = s.objects["cup"], layout.object("target").position
    d, tilt, base = _xy_distance(cup.position, target), _tilt_deg(cup), cup.position[2]
    on_table = base <= ON_TABLE
    reason = (f"cup {d * 100:.1f} cm from the target's centre (needs <= {PLACE_RADIUS * 100:.0f}), "
              f"tilted {tilt:.0f} deg (needs <= {UPRIGHT_DEG:.0f}), "
              + ("on the table" if on_table else f"its base {base * 100:.1f} cm up"))
    return Goal(d <= PLACE_RADIUS and tilt <= UPRIGHT_DEG and on_table, reason)


def _mug_points(shape) -> np.ndarray:
    """Points round a mug's base and rim and its handle's outer corners (body frame): its lowest is one."""
    r_bottom, r_top, h, _ = shape.size
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    rings = [np.stack([r * np.cos(a), r * np.sin(a), np.full_like(a, z)], axis=1)
             for r, z in ((r_bottom, 0.0), (r_top, h))]
    cx, cz = mug_handle_hole(shape)
    out = cx + HANDLE_HOLE[0] / 2 + HANDLE_BAR
    reach = HANDLE_HOLE[1] / 2 + HANDLE_BAR
    handle = np.array([[out, 0.0, cz - reach], [out, 0.0, cz + reach]])
    return np.concatenate(rings + [handle])


def _hang(layout: Layout, s: WorldState) -> Goal:
    # The mug hangs from the peg: the peg's axis passes through its handle's hole, and its lowest point is
    # clear of the table (with "let go and at rest", nothing but the peg holds it up).
    mug, peg = s.objects["mug"], layout.object("peg")
    shape = layout.object("mug").shape
    r = mug.rotation
    # The peg's axis (its x, through its centre) in the mug's frame, where the handle's hole is a rectangle
    # in the plane y = 0 around mug_handle_hole.
    p = r.T @ (np.asarray(peg.position) - np.asarray(mug.position))
    d = r.T @ np.array([math.cos(peg.yaw), math.sin(peg.yaw), 0.0])
    through = False
    if abs(d[1]) > 0.3:
        along = -p[1] / d[1]
        hit = p + along * d
        cx, cz = mug_handle_hole(shape)
        through = (abs(hit[0] - cx) < HANDLE_HOLE[0] / 2 and abs(hit[2] - cz) < HANDLE_HOLE[1] / 2
                   and abs(along) <= peg.shape.size[0] / 2)
    lowest = mug.position[2] + float((_mug_points(shape) @ r.T)[:, 2].min())
    clear = lowest >= HANG_CLEARANCE
    reason = (("the peg through the mug's handle" if through else "the peg not through the mug's handle")
              + f", its lowest point {lowest * 100:.1f} cm above the table (needs >= {HANG_CLEARANCE * 100:.0f})")
    return Goal(through and clear, reason)


def _pour(layout: Layout, s: WorldState) -> Goal:
    bowl = s.objects["bowl"]
    r_bottom, r_top, h, _ = layout.object("bowl").shape.size
    inside = 0
    balls = [o for n, o in s.objects.items() if n.startswith("ball")]
    for ball in balls:
        local = bowl.rotation.T @ (np.asarray(ball.position) - np.asarray(bowl.position))
        rim = r_bottom + (r_top - r_bottom) * local[2] / h
        inside += int(0.0 < local[2] < h + 0.005 and math.hypot(local[0], local[1]) < rim)
    return Goal(inside >= POUR_NEEDED, f"{inside} of {len(balls)} balls in the bowl (needs {POUR_NEEDED})")


def _box_rotation(layout: Layout, s: WorldState) -> Goal:
    box, start = s.objects["box"], layout.object("box")
    yaw = math.atan2(box.rotation[1, 0], box.rotation[0, 0])
    turned = (yaw - start.yaw) % math.pi  # a box looks the same turned half way round
    turned = math.degrees(min(turned, math.pi - turned))
    tilt, height = _tilt_deg(box), box.position[2] - start.shape.size[2] / 2
    flat = tilt <= UPRIGHT_DEG and abs(height) <= ON_TABLE
    reason = (f"box turned {turned:.0f} deg about the vertical (needs >= {TURN_DEG:.0f}), "
              + ("lying flat on the table" if flat else f"not flat on the table (tilted {tilt:.0f} deg)"))
    return Goal(turned >= TURN_DEG and flat, reason)


def _cup_stack(layout: Layout, s: WorldState) -> Goal:
    cups = sorted((o for n, o in s.objects.items() if n.startswith("cup")), key=lambda o: o.position[2])
    bottom = cups[0]
    if bottom.position[2] > ON_TABLE or _tilt_deg(bottom) > UPRIGHT_DEG:
        return Goal(False, f"the lowest cup ({bottom.name}) is not standing on the table")
    for below, above in pairwise(cups):
        offset = _xy_distance(above.position, below.position)
        rise = above.position[2] - below.position[2]
        if offset > STACK_OFFSET or not STACK_RISE[0] <= rise <= STACK_RISE[1] or _tilt_deg(above) > UPRIGHT_DEG:
            return Goal(False, f"{above.name} is not nested in {below.name} ({offset * 100:.1f} cm off its axis, "
                               f"{rise * 100:.1f} cm above its base; needs <= {STACK_OFFSET * 100:.1f} and "
                               f"{STACK_RISE[0] * 100:.1f}..{STACK_RISE[1] * 100:.0f})")
    order = " in ".join(o.name for o in reversed(cups))
    return Goal(True, f"cups nested upright on the table ({order})")


GOALS: dict[str, Callable[[Layout, WorldState], Goal]] = {
    "pick_place": _pick_place, "hang": _hang, "pour": _pour, "box_rotation": _box_rotation, "cup_stack": _cup_stack,
}


def goal(layout: Layout, state: WorldState) -> Goal:
    """Whether the task's goal holds in one state (not yet whether it lasts)."""
    return GOALS[layout.task](layout, state)


def _unsettled(state: WorldState) -> str:
    """"" or what is not let go / at rest in this state."""
    for o in state.objects.values():
        if o.touching_robot:
            return f"the robot still touches {o.name}"
        if o.speed > REST_SPEED or o.spin > REST_SPIN:
            return f"{o.name} still moving ({o.speed * 100:.1f} cm/s, {o.spin:.2f} rad/s)"
    return ""


def judge(layout: Layout, states: Sequence[WorldState]) -> Outcome:
    """The episode's outcome from its world states (time order, a few per 0.1 s or more): success when the
    goal holds, everything let go and at rest, through the last REST_S seconds."""
    if not states:
        return Outcome(layout.task, False, "no world state recorded", 0)
    last = states[-1]
    start_ns = last.time_ns - int(REST_S * 1e9)
    end = goal(layout, last)
    if not end.held:
        return Outcome(layout.task, False, end.reason, last.time_ns)
    if states[0].time_ns > start_ns:
        return Outcome(layout.task, False, f"{end.reason}, but for less than {REST_S:g} s", last.time_ns)
    for s in states:
        if s.time_ns < start_ns:
            continue
        at = f" at {(s.time_ns - states[0].time_ns) / 1e9:.2f} s"
        g = goal(layout, s)
        if not g.held:
            return Outcome(layout.task, False, f"{g.reason}{at}: not yet for {REST_S:g} s", last.time_ns)
        unsettled = _unsettled(s)
        if unsettled:
            return Outcome(layout.task, False, f"{end.reason}, but {unsettled}{at}", last.time_ns)
    return Outcome(layout.task, True, f"{end.reason}; let go and at rest for {REST_S:g} s", last.time_ns)
