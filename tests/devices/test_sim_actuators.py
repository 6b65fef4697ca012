"""SimArm and SimHand follow commands kinematically and never exceed their limits, step by step."""

import time

import numpy as np
import pytest

from teleprev.devices.contract import DeviceContext
from teleprev_devices.sim.arm import ArmSettings, SimArm
from teleprev_devices.sim.follow import JointFollower
from teleprev_devices.sim.hand import HandSettings, SimHand
from teleprev_devices.sim.world import shared_world
from teleprev.errors import ConfigError, DeviceError
from teleprev.messages import JointSample
from teleprev.clock import SessionClock

LEAP = tuple(str(i) for i in range(16))


def context(robot="xarm6_leap_hand", end_effector="leap_hand"):
    return DeviceContext(clock=SessionClock(), robot=robot, end_effector=end_effector)


def run(device, command, seconds, settle=0.1):
    """States for `seconds` of real time, with `command` sent after `settle` seconds."""
    device.connect()
    states, sent = [], False
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        if not sent and time.monotonic() - t0 > settle:
            device.send(command)
            sent = True
        states += [s.payload for s in device.read(0.05)]
    device.disconnect()
    return states


def check_limits(states, period, vmax, amax=None):
    q = np.array([s.positions for s in states])
    v = np.array([s.velocities for s in states])
    stamps = np.array([s.stamp_ns for s in states])
    assert np.abs(np.diff(stamps) / 1e9 - period).max() < 1e-3  # one state per step, none missing
    step = np.abs(np.diff(q, axis=0))
    assert np.all(step <= vmax * period * (1 + 1e-9)), f"max speed {(step / period).max(axis=0)}"
    assert np.all(np.abs(v) <= vmax * (1 + 1e-9))
    if amax is not None:
        assert np.all(np.abs(np.diff(v, axis=0)) <= amax * period * (1 + 1e-9))
    return q


def test_arm_moves_to_the_command_at_its_velocity_and_acceleration_limits():
    ctx = context()
    arm = SimArm("arm", ArmSettings(), ctx)
    home = np.array(arm.settings.home)
    target = home + np.array([1.8, 0.4, -0.6, 0.5, 0.0, -1.0])
    states = run(arm, JointSample(0, arm.joint_names, target), 1.3)
    assert states[0].names == arm.joint_names == tuple(f"joint{i}" for i in range(1, 7))
    q = check_limits(states, 0.01, 3.14, amax=10.0)
    assert np.allclose(q[0], home)
    assert np.allclose(q[-1], target, atol=1e-6)
    # joint1 travels 1.8 rad: at best 0.314 s to reach 3.14 rad/s, so about 0.89 s in all.
    moving = np.flatnonzero(np.abs(q[:, 0] - home[0]) > 1e-9)
    arrived = np.flatnonzero(np.abs(q[:, 0] - target[0]) < 1e-6)
    assert (arrived[0] - moving[0] + 1) * 0.01 >= 1.8 / 3.14 + 0.3
    assert np.abs(np.diff(q[:, 0]) / 0.01).max() == pytest.approx(3.14, rel=1e-6)  # it does reach the limit
    assert np.allclose(shared_world(ctx).joints()[:6], target, atol=1e-6)  # the camera sees it there


def test_arm_partial_commands_keep_the_other_joints_and_bad_commands_are_refused():
    arm = SimArm("arm", ArmSettings(max_velocity=2.0), context())
    states = run(arm, JointSample(0, ("joint2",), np.array([0.0])), 0.5, settle=0.05)
    q = check_limits(states, 0.01, 2.0, amax=10.0)
    assert np.allclose(q[-1], np.array(arm.settings.home) * np.array([1, 0, 1, 1, 1, 1]), atol=1e-6)
    arm.connect()
    with pytest.raises(DeviceError, match="unknown joints"):
        arm.send(JointSample(0, ("joint9",), np.array([0.0])))
    with pytest.raises(DeviceError, match="finite"):
        arm.send(JointSample(0, ("joint1",), np.array([np.nan])))
    arm.disconnect()


def test_leap_hand_follows_within_its_speed_limit():
    ctx = context()
    hand = SimHand("hand", HandSettings(), ctx)
    fist = np.r_[[0.0, 1.6, 1.7, 1.2] * 3, [1.0, 0.8, 0.6, 0.6]]
    states = run(hand, JointSample(0, LEAP, fist), 0.55, settle=0.05)
    assert states[0].names == LEAP
    q = check_limits(states, 1 / 90, 8.48)
    assert np.allclose(q[0], 0.0) and np.allclose(q[-1], fist, atol=1e-6)
    assert np.allclose(shared_world(ctx).joints()[6:], fist, atol=1e-6)


def test_parallel_gripper_closes_at_its_speed():
    hand = SimHand("gripper", HandSettings(), context("xarm6_parallel_gripper", "parallel_gripper"))
    states = run(hand, JointSample(0, ("gripper",), np.array([0.0])), 0.8, settle=0.05)
    q = check_limits(states, 1 / 90, 0.15)
    assert q[0, 0] == pytest.approx(0.085) and q[-1, 0] == pytest.approx(0.0, abs=1e-9)
    closing = np.flatnonzero((q[:, 0] < 0.085 - 1e-9) & (q[:, 0] > 1e-9))
    assert len(closing) / 90 >= 0.085 / 0.15 - 2 / 90


def test_vacuum_switches_after_its_switch_time():
    ctx = context("xarm6_vacuum", "vacuum")
    hand = SimHand("vac", HandSettings(switch_ms=60.0), ctx)
    hand.connect()
    states = [s.payload for s in hand.read(0.1)]
    hand.send(JointSample(0, ("vacuum",), np.array([1.0])))
    sent = hand.context.clock.now_ns()
    t_end = time.monotonic() + 0.3
    while time.monotonic() < t_end:
        states += [s.payload for s in hand.read(0.05)]
    hand.disconnect()
    values = np.array([s.positions[0] for s in states])
    assert set(values.tolist()) == {0.0, 1.0} and states[0].names == ("vacuum",)
    on = states[int(np.argmax(values))].stamp_ns
    assert 0.045 <= (on - sent) / 1e9 <= 0.09
    assert shared_world(ctx).vacuum_on


@pytest.mark.parametrize(
    "cls, settings, ctx_args, match",
    [
        (SimArm, ArmSettings(home=(0.0, 0.0, 0.0)), (), r"\[devices.x\].home: needs 6 values"),
        (SimArm, ArmSettings(home=(0.0, 3.0, 0.0, 0.0, 0.0, 0.0)), (), r"home: outside the joint limits: joint2=3"),
        (SimArm, ArmSettings(max_velocity=5.0), (), r"max_velocity: 5 is above the URDF's limit"),
        (SimHand, HandSettings(home=(0.1,)), (), r"home: needs 16 values"),
        (SimHand, HandSettings(), ("xarm6_vacuum", "leap_hand"), r"has no joints .* check \[rig\] robot"),
    ],
)
def test_bad_settings_name_the_device_and_key(cls, settings, ctx_args, match):
    with pytest.raises(ConfigError, match=match):
        cls("x", settings, context(*ctx_args))


def test_follower_without_acceleration_limit_is_rate_limited_and_lands_exactly():
    f = JointFollower(np.zeros(2), -np.ones(2) * 3, np.ones(2) * 3, np.array([1.0, 2.0]))
    f.set_target(np.array([0.25, -0.3]))
    trace = []
    for _ in range(40):
        f.step(0.01)
        trace.append(f.q.copy())
    trace = np.array(trace)
    assert np.all(np.abs(np.diff(np.vstack([np.zeros(2), trace]), axis=0)) <= np.array([0.01, 0.02]) + 1e-12)
    assert np.array_equal(trace[-1], [0.25, -0.3])
    f.set_target(np.array([5.0, 5.0]))  # clipped to the limits
    for _ in range(400):
        f.step(0.01)
    assert np.array_equal(f.q, [3.0, 3.0])
