"""The physics world: all three end effectors load, drives follow targets by joint name, the session
clock steps it, layouts come from seeds, and the suction cup holds what it touches."""

from __future__ import annotations

import json
import math

import mujoco
import numpy as np
import pytest

from teleprev.robot.effectors import EFFECTORS
from teleprev.world import drives
from teleprev.world.layout import DEFAULT_ANCHOR, TASKS, layout_from_record, task_layout
from teleprev.world.world import ARM_HOME, PhysicsWorld
from tests.world.helpers import run

ARM = tuple(f"joint{i}" for i in range(1, 7))


@pytest.mark.parametrize("effector", sorted(EFFECTORS))
def test_every_end_effector_loads_with_every_task(effector):
    for task in TASKS:
        world = PhysicsWorld(effector, task_layout(task, 0))
        assert world.joint_names == ARM + EFFECTORS[effector].joints
        assert world.model.opt.timestep == pytest.approx(0.002)
        # Every moving body has mass (the parallel gripper's driver had none in its URDF: MuJoCo refused it).
        moving = [b for b in range(1, world.model.nbody) if world.model.body_dofnum[b] > 0]
        assert min(world.model.body_mass[moving]) > 0


def test_the_gripper_driver_has_the_urdf_inertia():
    world = PhysicsWorld("parallel_gripper", task_layout("pick_place", 0))
    body = world.model.body("gripper_driver")
    assert body.mass[0] == pytest.approx(0.05)
    assert sorted(body.inertia) == pytest.approx(sorted([1.667e-05, 5.417e-06, 1.875e-05]), rel=1e-3)


def test_the_robot_starts_at_home_and_holds_it():
    world = PhysicsWorld("leap_hand", task_layout("pick_place", 0))
    run(world, 0.5)
    q = world.joint_positions(ARM)
    assert [q[n] for n in ARM] == pytest.approx(ARM_HOME, abs=2e-3)  # gravity compensated, stiff servo
    # The layout's anchor is the TCP at that home pose.
    assert world.tcp()[:3, 3] == pytest.approx(DEFAULT_ANCHOR, abs=0.01)


def test_arm_and_hand_follow_targets_by_name():
    world = PhysicsWorld("leap_hand", task_layout("pick_place", 0))
    targets = {"joint1": 0.25, "joint5": -0.6, "1": 1.0, "12": 0.8, "0": 0.3}
    world.set_targets(targets)
    run(world, 0.6)
    q = world.joint_positions(targets)
    assert q["joint1"] == pytest.approx(0.25, abs=2e-3) and q["joint5"] == pytest.approx(-0.6, abs=2e-3)
    for finger in ("1", "12", "0"):  # the Dynamixels' soft loop sags a little under the fingers' weight
        assert q[finger] == pytest.approx(targets[finger], abs=0.04)
    assert world.targets(["joint1"]) == {"joint1": 0.25}


def test_the_arm_tracks_a_ramp_with_a_small_lag():
    world = PhysicsWorld("leap_hand", task_layout("pick_place", 0))
    for k in range(250):  # 1 rad/s on joint1 for 0.5 s, a new target every step
        world.set_targets({"joint1": k * 0.002})
        world.step()
    lag = world.targets(["joint1"])["joint1"] - world.joint_positions(["joint1"])["joint1"]
    assert 0.0 < lag < 0.012


def test_the_hand_drives_are_the_dynamixel_registers_in_si_units():
    leap = drives.LEAP
    assert leap.kp == pytest.approx(600 / 128 * 4096 / (2 * math.pi) * 0.93 / 1800, rel=1e-9)
    assert (leap.kp, leap.kd, leap.force_limit) == pytest.approx((1.58, 4.2e-3, 0.284), rel=0.01)
    world = PhysicsWorld("leap_hand", task_layout("pick_place", 0))
    index, side = world.model.actuator("1"), world.model.actuator("0")
    assert index.gainprm[0] == pytest.approx(leap.kp) and index.biasprm[2] == pytest.approx(-leap.kd)
    assert index.forcerange == pytest.approx([-leap.force_limit, leap.force_limit])
    assert side.gainprm[0] == pytest.approx(drives.LEAP_SIDE.kp)
    assert drives.LEAP_SIDE.kp == pytest.approx(0.75 * leap.kp)


def test_a_finger_pushing_on_the_table_is_held_back_by_its_current_limit():
    world = PhysicsWorld("leap_hand", task_layout("pick_place", 0))
    world.set_targets({"1": 2.2})  # curled hard into nothing: the drive saturates at its torque limit
    world.step(5)
    force = world.data.actuator_force[world.model.actuator("1").id]
    assert abs(force) == pytest.approx(drives.LEAP.force_limit, rel=1e-6)


def test_advance_to_steps_at_500_hz_on_the_session_clock():
    world = PhysicsWorld("vacuum", task_layout("box_rotation", 0), start_ns=10_000_000_000)
    assert world.advance_to(10_000_000_000 + 10_500_000) == 5
    assert world.time_ns == 10_010_000_000
    assert world.advance_to(10_000_000_000) == 0  # never backwards
    with pytest.raises(ValueError, match="500 Hz or more"):
        PhysicsWorld("vacuum", task_layout("box_rotation", 0), rate_hz=250)


def test_joints_are_named_and_unknown_names_are_refused():
    world = PhysicsWorld("parallel_gripper", task_layout("pick_place", 0))
    with pytest.raises(KeyError, match="'7'.*gripper"):
        world.set_targets({"7": 0.1})
    with pytest.raises(ValueError, match="finite"):
        world.set_targets({"gripper": float("nan")})


def test_the_gripper_jaws_follow_the_opening():
    world = PhysicsWorld("parallel_gripper", task_layout("pick_place", 0))
    assert world.joint_positions(["gripper"])["gripper"] == pytest.approx(0.085, abs=1e-4)
    world.set_targets({"gripper": 0.02})
    run(world, 0.3)
    assert world.joint_positions(["gripper"])["gripper"] > 0.035  # no faster than 0.15 m/s
    run(world, 0.5)
    assert world.joint_positions(["gripper"])["gripper"] == pytest.approx(0.02, abs=1e-3)
    left = world.data.qpos[world.model.jnt_qposadr[world.model.joint("jaw_left_joint").id]]
    assert left == pytest.approx(0.01, abs=1e-3)  # the URDF's mimic: half the opening each


def test_layouts_come_from_the_seed_at_the_sim_rigs_places():
    a, b, c = task_layout("pick_place", 3), task_layout("pick_place", 3), task_layout("pick_place", 4)
    assert a == b and a != c
    cup = a.object("cup").position
    # The kinematic sim's nominal spot (0.10, -0.10) from the resting wrist, with at most 2 cm of jitter.
    assert abs(cup[0] - DEFAULT_ANCHOR[0] - 0.10) <= 0.02 + 1e-9 and abs(cup[1] + 0.10) <= 0.02 + 1e-9
    assert cup[2] == 0.0
    with pytest.raises(ValueError, match="unknown task 'juggle'"):
        task_layout("juggle", 0)


def test_the_same_commands_give_the_same_world():
    def play():
        world = PhysicsWorld("leap_hand", task_layout("pour", 9))
        for k in range(100):
            world.set_targets({"joint2": -0.27 - 0.001 * k, "1": 0.01 * k})
            world.step(2)
        return world.state()

    assert play() == play()


def test_the_state_is_a_json_record_of_every_free_object():
    world = PhysicsWorld("leap_hand", task_layout("pour", 2))
    state = run(world, 0.1)[-1]
    record = json.loads(json.dumps(state.to_record()))
    assert record["time_ns"] == 100_000_000
    assert set(record["objects"]) == {"cup", "bowl"} | {f"ball{i}" for i in range(1, 11)}
    assert record["objects"]["bowl"]["position"] == pytest.approx(list(state.objects["bowl"].position))


def test_objects_rest_on_the_table_and_fall_when_dropped():
    world = PhysicsWorld("leap_hand", task_layout("box_rotation", 0))
    box = world.layout.object("box")
    run(world, 0.3)
    assert world.state().objects["box"].position == pytest.approx(box.position, abs=2e-3)
    world.place_object("box", (box.position[0], box.position[1], 0.15))  # below the hand
    assert not world.state().objects["box"].touching_robot
    run(world, 0.5)
    assert world.state().objects["box"].position[2] == pytest.approx(0.04, abs=3e-3)


def _box_on_the_suction_cup(world: PhysicsWorld) -> None:
    tcp = world.tcp()
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, tcp[:3, :3].flatten())  # the box's z along the tool's axis
    world.place_object("box", tcp[:3, 3] + tcp[:3, 2] * (0.04 + 0.001), quat)


@pytest.mark.parametrize("suction", [1.0, 0.0])
def test_the_vacuum_holds_what_its_cup_touches_only_while_on(suction):
    world = PhysicsWorld("vacuum", task_layout("box_rotation", 0))
    world.set_targets({"vacuum": suction})
    _box_on_the_suction_cup(world)
    run(world, 0.6)
    gap = np.linalg.norm(np.asarray(world.state().objects["box"].position) - world.tcp()[:3, 3])
    if suction:
        assert gap < 0.06 and world.state().objects["box"].touching_robot
    else:
        assert gap > 0.15 and world.joint_positions(["vacuum"]) == {"vacuum": 0.0}


def test_the_gripper_holds_a_cup_it_closed_on_while_the_arm_moves():
    world = PhysicsWorld("parallel_gripper", task_layout("pick_place", 0))
    base = world.data.body("gripper_base")
    rotation, origin = base.xmat.reshape(3, 3).copy(), base.xpos.copy()
    cup_axes = np.stack([rotation[:, 1], rotation[:, 2], rotation[:, 0]], axis=1)  # lying across the jaws
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, cup_axes.flatten())
    world.set_targets({"gripper": 0.0})
    for _ in range(40):  # handed over: held between the jaws until they have closed on it
        world.place_object("cup", origin + rotation @ [0.0, 0.0, 0.13] - cup_axes[:, 2] * 0.05, quat)
        world.step(5)
    run(world, 0.3)
    # The jaws stop on the cup's sides (7.4 cm across there), squeezing it.
    jaws = sum(world.data.qpos[world.model.jnt_qposadr[world.model.joint(j).id]]
               for j in ("jaw_left_joint", "jaw_right_joint"))
    assert jaws == pytest.approx(0.074, abs=0.003)

    def cup_in_gripper() -> np.ndarray:
        b = world.data.body("gripper_base")
        return b.xmat.reshape(3, 3).T @ (np.asarray(world.state().objects["cup"].position) - b.xpos)

    held, start = cup_in_gripper(), np.asarray(world.state().objects["cup"].position)
    q0 = world.joint_positions(["joint2", "joint3"])
    for k in range(100):  # a smooth 1 s move, as the pipeline's jerk-limited commands are
        a = 0.5 - 0.5 * np.cos(np.pi * (k + 1) / 100)
        world.set_targets({"joint2": q0["joint2"] - 0.25 * a, "joint3": q0["joint3"] - 0.2 * a})
        world.step(5)
    run(world, 0.3)
    assert np.linalg.norm(np.asarray(world.state().objects["cup"].position) - start) > 0.15  # carried along
    assert np.linalg.norm(cup_in_gripper() - held) < 0.005 and world.state().objects["cup"].touching_robot


def test_a_layout_record_restores_the_recorded_scene():
    layout = task_layout("cup_stack", 11)
    record = json.loads(json.dumps(layout.to_record()))
    assert record["task"] == "cup_stack" and record["seed"] == 11
    assert layout_from_record(record) == layout
    record["objects"]["cup2"]["position"][0] += 0.05  # where the recording says it stood wins
    moved = layout_from_record(record).object("cup2").position[0]
    assert moved == pytest.approx(layout.object("cup2").position[0] + 0.05)
    del record["objects"]["cup3"]
    with pytest.raises(ValueError, match="not the cup_stack task's"):
        layout_from_record(record)
    with pytest.raises(ValueError, match="needs task, seed"):
        layout_from_record({"task": "pour"})
