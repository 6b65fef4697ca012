"""SimArm and SimHand follow commands kinematically and never exceed their limits, step by step."""

import time

import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.errors import ConfigError, DeviceError
from teleprev.messages import JointSample
from teleprev_devices.sim.arm import ArmSettings, SimArm
from teleprev_devices.sim.follow import JointFollower
from teleprev_devices.sim.hand import HandSettings, SimHand
from teleprev_devices.sim.world import shared_world

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


def smooth_stream(home, t0_ns, distance, seconds=0.6, rate=120.0):
    """Commands of a minimum-jerk move by `distance` rad (joint1; the others less), stamped from t0_ns:
    peak acceleration 5.77 d / T^2, peak jerk 60 d / T^3."""
    tau = np.arange(1, int(seconds * rate) + 1) / (seconds * rate)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    direction = np.array([1.0, 0.5, -0.5, 1.0, 0.3, -1.0])
    return [(t0_ns + int(round(tk * seconds * 1e9)), home + distance * sk * direction) for tk, sk in zip(tau, s)]


def drive(arm, stream, pace=True):
    """Send a stamped command stream at its pace, reading states meanwhile; returns states and faults."""
    states, faults = [], []
    for stamp, q in stream:
        while pace and arm.context.clock.now_ns() < stamp:
            try:
                states += [s.payload for s in arm.read(0.002)]
            except DeviceError as exc:
                faults.append(str(exc))
        try:
            arm.send(JointSample(stamp, arm.joint_names, q))
        except DeviceError as exc:
            faults.append(str(exc))
    for _ in range(10):
        try:
            states += [s.payload for s in arm.read(0.02)]
        except DeviceError as exc:
            faults.append(str(exc))
    return states, faults


def test_arm_in_servo_mode_runs_a_smooth_stream_at_once_without_fault():
    ctx = context()
    arm = SimArm("arm", ArmSettings(), ctx)
    home = np.array(arm.settings.home)
    arm.connect()
    stream = smooth_stream(home, ctx.clock.now_ns() + 50_000_000, 0.5)  # 8 rad/s^2, 139 rad/s^3: within
    states, faults = drive(arm, stream)
    arm.disconnect()
    assert faults == [] and arm.fault == ""
    q = check_limits(states, 0.01, 3.14)
    assert np.allclose(q[-1], stream[-1][1], atol=1e-9)  # no filtering on the arm's side: it is where it was told
    assert np.allclose(shared_world(ctx).joints()[:6], stream[-1][1], atol=1e-9)


@pytest.mark.parametrize("scale, what", [(1.0, "accelerates"), (None, "jerks")])
def test_arm_faults_on_a_command_over_its_limits_and_stops_until_reconnected(scale, what):
    ctx = context()
    arm = SimArm("arm", ArmSettings(), ctx)
    home = np.array(arm.settings.home)
    arm.connect()
    t0 = ctx.clock.now_ns() + 50_000_000
    if scale is not None:  # peak acceleration 13.8 rad/s^2 (38% over), jerk 288 rad/s^3 (within)
        stream = smooth_stream(home, t0, 0.6, seconds=0.5)
    else:  # at 0.02 rad/s, then a step to 10 rad/s^2 (the limit):
        # jerk by divided differences 10 / (2 x 8.3 ms) = 600 rad/s^3
        t = np.arange(1, 40) / 120.0
        ramp = np.maximum(t - 20 / 120.0, 0.0)
        stream = [(t0 + int(round(tk * 1e9)), home + (0.02 * tk + 5.0 * rk**2) * np.ones(6)) for tk, rk in zip(t, ramp)]
    states, faults = drive(arm, stream)
    assert faults and what in faults[0] and "controller fault" in faults[0] and "+ 10%" in faults[0]
    assert any("reconnect to clear" in f for f in faults[1:])  # later commands are refused
    stopped = arm.follower.q.copy()
    assert np.all(np.abs(arm.follower.v) == 0.0)
    arm.disconnect()
    arm.connect()  # clearing the fault: the arm is where it stopped, commands are taken again
    assert arm.fault == "" and np.allclose(arm.follower.q, stopped)
    arm.send(JointSample(ctx.clock.now_ns(), arm.joint_names, stopped))
    arm.disconnect()


def test_arm_faults_on_a_jump_from_rest():
    ctx = context()
    arm = SimArm("arm", ArmSettings(), ctx)
    arm.connect()
    target = np.array(arm.settings.home) + np.array([0.05, 0, 0, 0, 0, 0])
    arm.send(JointSample(ctx.clock.now_ns(), arm.joint_names, target))
    assert "controller fault" in arm.fault and "joint1" in arm.fault
    with pytest.raises(DeviceError, match="accelerates joint1"):
        arm.read(0.05)
    arm.disconnect()


def test_arm_partial_commands_keep_the_other_joints_and_bad_commands_are_refused():
    arm = SimArm("arm", ArmSettings(max_velocity=2.0, max_acceleration=1e6, max_jerk=1e9), context())
    states = run(arm, JointSample(0, ("joint2",), np.array([0.0])), 0.5, settle=0.05)
    q = check_limits(states, 0.01, 2.0)
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


def test_after_a_pause_the_arm_stands_on_the_last_command_even_if_its_simulation_was_starved():
    """A servo-mode arm runs each target at once, so after a pause of more than STREAM_GAP_NS it stands
    on the last command. Its simulated state is stepped in read(); a process starved of CPU may not have
    stepped it, so the arm must not take that stale (moving) state as the start of the next stream, and
    a jump after the pause must still fault."""
    ctx = context()
    arm = SimArm("arm", ArmSettings(), ctx)
    home = np.array(arm.settings.home)
    arm.connect()
    t0 = ctx.clock.now_ns() + 50_000_000
    stream = smooth_stream(home, t0, 0.5)[:30]  # part way: still moving at the last command
    for stamp, q in stream:
        arm.send(JointSample(stamp, arm.joint_names, q))  # and no read(): the follower is never stepped
    assert arm.fault == "" and not np.allclose(arm.follower.q, stream[-1][1])  # the simulation lags behind
    last_t, last_q = stream[-1]
    # 100 ms later, a command one short step from rest at the last command (what the pipeline sends)
    arm.send(JointSample(last_t + 100_000_000, arm.joint_names, last_q + 0.5 * 5.0 * 0.01**2))
    assert arm.fault == ""
    arm.send(JointSample(last_t + 300_000_000, arm.joint_names, last_q + 0.05))  # a jump after a pause
    assert "controller fault" in arm.fault
    arm.disconnect()
