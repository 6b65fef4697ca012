"""Each task's success from the physics state: an untouched world fails, a world where the goal was put
in place (the object teleported there, then left to settle under gravity) succeeds, and the reason
says why in words."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from teleprev.world import success
from teleprev.world.build import mug_handle_hole
from teleprev.world.layout import POUR_BALLS, TASKS, task_layout
from teleprev.world.world import PhysicsWorld
from tests.world.helpers import run


def _yaw(angle: float) -> tuple[float, float, float, float]:
    return (math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2))


def _put_cup_on_target(world: PhysicsWorld) -> None:
    t = world.layout.object("target").position
    world.place_object("cup", (t[0] + 0.01, t[1] - 0.01, 0.01))


def _hang_mug(world: PhysicsWorld) -> None:
    peg = world.layout.object("peg")
    cx, cz = mug_handle_hole(world.layout.object("mug").shape)
    # Upright, the handle's hole round the peg and its top bar just over it (then it swings from the peg).
    yaw = peg.yaw - math.pi / 2  # the mug's y (the hole's axis) along the peg
    hole = np.array([cx * math.cos(yaw), cx * math.sin(yaw), cz])
    world.place_object("mug", np.asarray(peg.position) + [0.0, 0.0, 0.011] - hole, _yaw(yaw))
    run(world, 1.0)  # it swings on the peg a moment, as a hung mug does, then hangs still


def _balls_into_bowl(world: PhysicsWorld) -> None:
    bowl = world.layout.object("bowl").position
    # One layer on the bowl's floor: a ring of 7 and 3 inside it (a ball balanced on another rolls off later).
    spots = [(0.03, 2 * math.pi * i / 7) for i in range(7)] + [(0.012, 2 * math.pi * i / 3) for i in range(3)]
    for i, (r, a) in enumerate(spots[:POUR_BALLS]):
        world.place_object(f"ball{i + 1}", (bowl[0] + r * math.cos(a), bowl[1] + r * math.sin(a), 0.015))


def _turn_box(world: PhysicsWorld) -> None:
    box = world.layout.object("box")
    world.place_object("box", (box.position[0], box.position[1], box.position[2] + 0.002), _yaw(box.yaw + math.pi / 2))


def _stack_cups(world: PhysicsWorld) -> None:
    base = world.layout.object("cup3").position
    world.place_object("cup1", (base[0], base[1], 0.05))
    world.place_object("cup2", (base[0], base[1], 0.10))


DONE = {"pick_place": _put_cup_on_target, "hang": _hang_mug, "pour": _balls_into_bowl, "box_rotation": _turn_box,
        "cup_stack": _stack_cups}
FAILED_BECAUSE = {"pick_place": "cm from the target's centre", "hang": "the peg not through the mug's handle",
                  "pour": "0 of 10 balls in the bowl", "box_rotation": "box turned 0 deg",
                  "cup_stack": "is not nested in"}
SUCCEEDED_BECAUSE = {"pick_place": "on the table", "hang": "the peg through the mug's handle",
                     "pour": "10 of 10 balls in the bowl", "box_rotation": "box turned 90 deg",
                     "cup_stack": "cups nested upright"}


@pytest.mark.parametrize("task", TASKS)
def test_an_untouched_world_fails(task):
    layout = task_layout(task, 5)
    outcome = success.judge(layout, run(PhysicsWorld("leap_hand", layout), 1.0))
    assert not outcome.success and outcome.mark == "failure"
    assert FAILED_BECAUSE[task] in outcome.reason


@pytest.mark.parametrize("task", TASKS)
def test_the_goal_put_in_place_and_settled_succeeds(task):
    layout = task_layout(task, 5)
    world = PhysicsWorld("leap_hand", layout)
    run(world, 0.2)
    DONE[task](world)
    states = run(world, 1.5)
    outcome = success.judge(layout, states)
    assert outcome.success, outcome.reason
    assert outcome.mark == "success" and outcome.time_ns == states[-1].time_ns
    assert SUCCEEDED_BECAUSE[task] in outcome.reason and "at rest for 0.5 s" in outcome.reason
    # Judged right after the teleport the same goal has not lasted long enough (or is still moving).
    early = success.judge(layout, states[:10])
    assert not early.success and ("less than 0.5 s" in early.reason or "moving" in early.reason)


def test_a_goal_that_does_not_last_fails():
    layout = task_layout("box_rotation", 1)
    world = PhysicsWorld("vacuum", layout)
    _turn_box(world)
    states = run(world, 1.0)
    assert success.judge(layout, states).success
    world.place_object("box", layout.object("box").position, _yaw(layout.object("box").yaw))  # turned back
    outcome = success.judge(layout, states + run(world, 0.2))
    assert not outcome.success and "box turned 0 deg" in outcome.reason


def test_an_object_still_moving_or_held_is_not_done():
    layout = task_layout("pick_place", 2)
    world = PhysicsWorld("leap_hand", layout)
    _put_cup_on_target(world)
    states = run(world, 1.0)
    cup = states[-1].objects["cup"]
    sliding = type(states[-1])(states[-1].time_ns, {"cup": type(cup)(
        cup.name, cup.position, cup.quaternion, (0.05, 0.0, 0.0), cup.angular_velocity, False)})
    held = type(states[-1])(states[-1].time_ns, {"cup": type(cup)(
        cup.name, cup.position, cup.quaternion, cup.linear_velocity, cup.angular_velocity, True)})
    assert "cup still moving (5.0 cm/s" in success.judge(layout, states[:-1] + [sliding]).reason
    assert "the robot still touches cup" in success.judge(layout, states[:-1] + [held]).reason
    assert not success.judge(layout, []).success


def test_a_cup_knocked_over_on_the_target_fails():
    layout = task_layout("pick_place", 3)
    world = PhysicsWorld("leap_hand", layout)
    t = layout.object("target").position
    on_its_side = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0)
    world.place_object("cup", (t[0], t[1], 0.05), on_its_side)
    outcome = success.judge(layout, run(world, 1.5))
    assert not outcome.success and re.search(r"tilted [89]\d deg", outcome.reason)
