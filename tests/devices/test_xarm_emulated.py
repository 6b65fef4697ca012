"""xarm.arm through the real xarm-python-sdk against the emulated controller (teleprev/emulators): a servo
session, the controller's own faults, injected faults reaching the user as one line and an error event,
and commands the controller must not get never leaving the host."""

from __future__ import annotations

import time

import numpy as np
import pytest
from xarm.wrapper import XArmAPI  # the real SDK: scripts/test.sh installs the xarm extra (a missing one fails here)

from teleprev.clock import SessionClock
from teleprev.devices import DeviceContext, DeviceError, DeviceRunner
from teleprev.emulators import xarm_wire as wire
from teleprev.emulators.wire_schedule import PlannedSend, from_session_clock, lateness_ns
from teleprev.emulators.xarm_controller import XArmController
from teleprev.messages import JointSample
from teleprev_devices.xarm import XArm, XArmSettings
from tests.helpers.hardware import CommandStream, EventLog
from tests.helpers.wait import wait_until


@pytest.fixture(scope="module")
def box():
    with XArmController(host=None).start() as b:
        yield b


class Session:
    """xarm.arm on a runner against `box`, with a 100 Hz stream of smooth commands."""

    def __init__(self, box, **settings):
        self.clock = SessionClock()
        self.arm = XArm("arm", XArmSettings(host=box.host, **settings), DeviceContext(self.clock))
        self.log = EventLog()
        self.runner = DeviceRunner(self.arm, self.log.sink, self.clock, reconnect_s=0.1).start()
        assert self.log.wait(lambda: self.log.count("connected") == 1), self.log.events
        self.stream = CommandStream(self.arm, self.clock).start()

    def stop(self):
        self.stream.stop()
        self.runner.stop()


@pytest.fixture
def session(box):
    s = Session(box, report_timeout_s=0.6)
    yield s
    s.stop()
    box.operator_clear()


def test_a_servo_session_through_the_sdk(box, session):
    before = len(box.commands)
    time.sleep(1.0)
    got = len(box.commands) - before
    assert got >= 80 and session.stream.failed == 0, (got, session.stream.last_error)
    assert session.log.states >= 80 and session.log.count("error") == 0
    assert box.faults == [] and not box.unknown  # nothing the controller refused or did not know
    assert (box.mode, box.enabled) == (wire.SERVO_MODE, True) and box.state == wire.MOVING
    for register in (wire.MOTION_EN, wire.SET_MODE, wire.SET_STATE, wire.GET_ERROR, wire.MOVE_SERVOJ):
        assert box.requests[register] > 0, register
    assert box.requests[wire.GET_JOINT_POS] == 0  # joint states come from the 30003 report, not from requests
    # each target is taken at once, and the state read back is the controller's
    assert np.allclose(box.commands[-1].target, box.angles)
    assert np.allclose(session.log.last_state.positions, box.angles, atol=0.02)


@pytest.mark.parametrize("fault, said", [
    ("collision", "controller error 31: Collision Caused Abnormal Current; the arm stopped"),
    ("joint_limit", "controller error 23: Joints Angle Exceed Limit"),
    ("estop", "controller error 1: The Emergency Stop Button on the xArm Controller is pushed in"),
    ("drop", "xArm controller"),  # a reply that never comes, or the connection seen closed: either says so
    ("silent_report", "report stream (port 30003) sent nothing for 0.6 s"),
    ("slow_replies", "no reply within 0.1 s (SDK code 3)"),
])
def test_a_fault_is_one_line_an_error_event_and_the_commands_stop(box, session, fault, said):
    log = session.log
    time.sleep(0.2)
    box.inject(fault)
    assert log.wait(lambda: log.count("error") >= 1, timeout_s=3.0), log.events
    first = log.of("error")[0]["message"]
    assert said in first and "\n" not in first, first
    if fault == "drop":
        assert "no reply within" in first or "connection lost" in first, first
    latched = fault in ("collision", "joint_limit", "estop")
    if latched:  # nothing moves until the operator clears it: the plugin does not clear, nor send
        received = len(box.commands)
        time.sleep(0.5)
        assert len(box.commands) == received and box.requests[wire.CLEAN_ERR] == 0
        assert session.runner.stats().connects == 1
        box.operator_clear()
    assert log.wait(lambda: log.count("connected") == 2, timeout_s=10.0), log.events  # the SDK reconnects
    received = len(box.commands)
    assert log.wait(lambda: len(box.commands) > received + 20, timeout_s=3.0)  # commanded again
    assert box.requests[wire.CLEAN_ERR] == 0


def sdk_servo(box, **options) -> XArmAPI:
    api = XArmAPI(box.host, is_radian=True, **options)
    assert api.connected
    assert (api.motion_enable(True), api.set_mode(1), api.set_state(0)) == (0, 0, 0)
    return api


def test_the_controller_faults_on_a_target_past_its_limits(box):
    api = sdk_servo(box, check_joint_limit=False)  # the SDK's own check would refuse a target past the table (-8)
    try:
        q = list(box.angles)
        q[1] += 0.15  # 0.15 rad at once: at least 5 rad/s (over 30 ms at most), past joint2's 3.14 rad/s
        assert api.set_servo_angle_j(q, is_radian=True) == 1  # "the controller has an error latched"
        assert api.get_err_warn_code() == (0, [wire.SPEED_LIMIT, 0])
        assert not np.allclose(box.angles, q[:6])  # the arm stopped where it was
        box.operator_clear()
        assert (api.motion_enable(True), api.set_state(0)) == (0, 0)
        q = list(box.angles)
        q[2] = 0.25  # past joint3's 0.191986 rad in the SDK's table for this series
        assert api.set_servo_angle_j(q, is_radian=True) == 1
        assert api.get_err_warn_code() == (0, [wire.JOINT_LIMIT, 0])
        # xarm.arm connecting now says what stopped the arm, and leaves the error for the operator
        arm = XArm("arm", XArmSettings(host=box.host), DeviceContext(SessionClock()))
        with pytest.raises(DeviceError, match="controller error 23: Joints Angle Exceed Limit; clear it on the arm"):
            arm.connect()
        assert box.requests[wire.CLEAN_ERR] == 0
    finally:
        api.disconnect()
        box.operator_clear()


def test_a_command_past_the_servo_rule_never_leaves_the_host(box):
    clock = SessionClock()
    arm = XArm("arm", XArmSettings(host=box.host), DeviceContext(clock))
    arm.connect()
    faults = len(box.faults)
    try:
        q = np.asarray(arm.read(0.5)[0].payload.positions)
        t = clock.now_ns()
        names = arm.joint_names
        arm.send(JointSample(t, names, q))  # at rest
        received = len(box.commands)
        jump = q.copy()
        jump[2] += 0.01  # 0.01 rad in 10 ms from rest: about 100 rad/s^2
        with pytest.raises(DeviceError, match=r"accelerates joint3 at .* rad/s\^2 \(limit 10 \+ 10%\).*would fault"):
            arm.send(JointSample(t + 10_000_000, names, jump))
        with pytest.raises(DeviceError, match="commands stopped after a fault"):
            arm.send(JointSample(t + 20_000_000, names, q))
        with pytest.raises(DeviceError, match="accelerates joint3"):
            arm.read(0.1)  # the runner records it as an error event: the session goes to preview
        assert len(box.commands) == received and arm.counters()["refused_commands"] == 1
        assert len(box.faults) == faults
    finally:
        arm.disconnect()


def test_the_arm_the_rig_names_must_be_the_one_connected():
    with XArmController(host=None, dof=7).start() as seven:
        arm = XArm("arm", XArmSettings(host=seven.host, dof=6), DeviceContext(SessionClock()))
        with pytest.raises(DeviceError, match="drives a 7-joint arm but the rig says dof = 6"):
            arm.connect()
        host = seven.host
    arm = XArm("arm", XArmSettings(host=host), DeviceContext(SessionClock()))  # nothing listens there now
    with pytest.raises(DeviceError, match=f"xArm controller {host}: cannot connect"):
        arm.connect()


class SlowStart(XArm):
    """xarm.arm on a controller slow to make ready (0.3 s from connect to servo mode): a reconnect holds the
    device's lock that long, while a command stream waits to start again."""

    def _start(self):
        q = super()._start()
        time.sleep(0.3)
        return q


def test_a_stream_starts_again_where_the_arm_stands_after_a_reconnect(box):
    """After a fault the arm may stand elsewhere (moved by hand); the command stream starts again from the
    position the reconnect measured, not from its last command before the fault, which the servo rule
    would refuse as a jump (and the next fault injected would land on an arm already down)."""
    clock = SessionClock()
    arm = SlowStart("arm", XArmSettings(host=box.host), DeviceContext(clock))
    log = EventLog()
    runner = DeviceRunner(arm, log.sink, clock, reconnect_s=0.1).start()
    stream = CommandStream(arm, clock)
    try:
        wait_until(lambda: log.count("connected") == 1, 10.0, what="the arm connected")
        stream.start()
        wait_until(lambda: stream.sent > 20, 5.0, what="commands streaming")
        box.inject("collision")
        wait_until(lambda: log.count("error") == 1, 3.0, what="the collision reported")
        with box._lock:
            box.angles = box.angles + 0.02  # the operator moves the stopped arm a little
        box.operator_clear()
        wait_until(lambda: log.count("connected") == 2, 10.0, what="the arm reconnected")
        sent = stream.sent
        wait_until(lambda: stream.sent > sent + 30, 5.0, what="commands streaming again")
        assert [e["message"] for e in log.of("error")][1:] == []
        assert np.abs(box.commands[-1].target - box.angles).max() < 0.05
    finally:
        stream.stop()
        runner.stop()
        box.operator_clear()


def test_lateness_is_each_arrival_against_the_instant_its_sender_planned():
    """wire_schedule: the box's arrival stamps paired with the sender's schedule (float32 on the wire), a
    target that left 30 ms after it was due shows 30 ms late, one planned but never sent is left out."""
    with XArmController(host=None).start() as b:
        api = sdk_servo(b)
        try:
            q, start, planned = np.array(b.angles), len(b.arrivals), []
            t0 = time.monotonic_ns() + 20_000_000
            for k in range(10):
                due = t0 + k * 10_000_000
                time.sleep(max(0.0, (due - time.monotonic_ns()) / 1e9) + (0.03 if k == 5 else 0.0))
                q[0] += 0.0003
                assert api.set_servo_angle_j(list(q), is_radian=True) == 0
                planned.append(PlannedSend(due, q.copy()))
                if k == 7:
                    planned.append(PlannedSend(due + 1, q + 0.1))  # refused before it left: never on the wire
            late = lateness_ns(planned, list(b.arrivals)[start:])
        finally:
            api.disconnect()
    assert len(late) == 10 and min(late) >= 0
    assert late[5] >= 30_000_000  # it left 30 ms after it was due
    clock = SessionClock()
    assert from_session_clock(clock, clock.from_monotonic(123_456_789), q).due_ns == 123_456_789
