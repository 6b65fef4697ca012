"""The execute gate's states and refusals, and the session loop's controls: typed, queued to the loop thread
(never carried out on the caller's), in the order they arrive."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import pytest

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.live.core.gate import ExecuteGate, GateState
from teleprev.live.core.loop import SessionLoop
from tests.helpers.wait import wait_until


def test_the_strongest_reason_wins_and_each_lifts_as_it_says():
    gate = ExecuteGate()
    assert gate.state is GateState.OPEN and gate.refusal(unattended=True) is None
    gate.faulted("device arm failed: boom")
    assert gate.state is GateState.FAULTED and gate.fault == "device arm failed: boom"
    assert gate.refusal(unattended=False) is None  # the operator's key is let through
    gate.hold("schedule", "resting")
    gate.hold("policy", "not acting yet")
    refusal = gate.refusal(unattended=False)
    assert refusal.state is GateState.HELD and refusal.why == "resting; not acting yet"
    gate.release("schedule")
    gate.release("policy")
    gate.release("nobody")  # a release without a hold changes nothing
    assert gate.state is GateState.FAULTED
    gate.halt("the recording failed")
    gate.engaged()  # clears the fault, never a halt
    assert gate.state is GateState.HALTED and gate.fault == ""
    assert gate.refusal(unattended=False) == gate.refusal(unattended=True)
    assert gate.refusal(unattended=False).why == "the recording failed"


def test_an_unattended_engage_after_a_fault_is_told_once_per_fault():
    gate = ExecuteGate()
    gate.faulted("device arm failed")
    told = [gate.refusal(unattended=True).tell for _ in range(3)]
    assert told == [True, False, False]
    assert "does not engage again after a fault" in gate.refusal(unattended=True).why
    gate.faulted("device arm failed again")
    assert gate.refusal(unattended=True).tell


def test_controls_wait_for_the_loop_thread_and_run_there_in_order():
    logged = []
    loop = SessionLoop(SessionClock(), logged.append)  # no pipeline: every engage is refused
    caller = threading.current_thread()
    ran_on = []
    loop.on_episode_start = lambda task: ran_on.append(threading.current_thread())
    loop.start_episode("pour")
    loop.hold("schedule", "resting")
    loop.engage()
    loop.release("schedule")
    loop.note("ready")
    assert loop.backlog() == 5 and loop.episodes.index == -1 and not logged  # nothing ran on this thread
    loop.start()
    try:
        wait_until(lambda: loop.backlog() == 0 and any(m.topic == topics.OPERATOR for m in logged), 5.0,
                   what="the loop thread to carry out the controls")
    finally:
        loop.stop()
    assert ran_on and ran_on[0] is not caller and ran_on[0].name == "session-loop"
    assert [m.topic for m in logged] == [topics.EPISODE, topics.OPERATOR]
    assert loop.snapshot.task == "pour" and loop.snapshot.episode == 0
    assert loop.snapshot.message == "cannot switch to execute: resting"  # refused while held, before the release
    assert loop.gate.state is GateState.OPEN


def test_a_hold_says_why():
    loop = SessionLoop(SessionClock(), lambda m: None)
    with pytest.raises(ValueError, match="says why"):
        loop.hold("schedule", "")


class _Driver:
    """The driver's side of a mode switch only (its mode, and every mode the loop asked it for); the samples
    it is fed step nothing."""

    pipeline = SimpleNamespace(arm_names=("joint1",), effector_names=("0",), cfg=SimpleNamespace(stale_ms=100.0))
    topics = SimpleNamespace(action="", arm="/arm/arm/state", hand="/glove/glove/hand")

    def __init__(self):
        self.mode, self.asked = "preview", []

    def request_mode(self, mode: str, t_ns: int) -> str:
        self.asked.append(mode)
        self.mode = "preview" if mode == "estop" else mode
        return ""

    def take_updates(self) -> list:
        return []

    def feed(self, msg) -> SimpleNamespace:  # a device event steps nothing
        return SimpleNamespace(result=None)


def test_an_actuator_failing_at_rest_halts_the_planner_once_after_an_engage():
    """In preview at rest the planner still keeps the arm's last command, which the next engage starts from
    while the controller holds it. An arm that fails has let go of it: the loop halts the planner (a
    recorded switch), once, so that the next engage starts from the measured arm. Before any engage, or for
    a camera, there is nothing to let go of."""
    from teleprev.messages import Event, Sample

    logged, driver = [], _Driver()
    ports = {"arm": SimpleNamespace(name="arm"), "hand": SimpleNamespace(name="hand")}
    loop = SessionLoop(SessionClock(), logged.append, driver, actuators=ports)

    def failed(device: str) -> None:
        loop.sink(Sample(topics.DEVICE_EVENT, Event(0, "teleprev.DeviceEvent", {"device": device, "event": "error",
                                                                               "message": "boom"})), 0)

    failed("arm")  # before any engage
    loop.engage()
    loop.to_preview("schedule")
    failed("cam_front")
    failed("arm")
    failed("arm")  # again: already halted
    loop.start()
    try:
        wait_until(lambda: loop.backlog() == 0 and len(loop.stats.device_failures) == 2 and
                   loop.stats.device_failures["arm"] == 3, 5.0, what="the loop to take the failures")
    finally:
        loop.stop()
    assert driver.asked == ["execute", "preview", "estop"]
    modes = [m.payload.data for m in logged if m.topic == topics.MODE]
    assert modes[-1] == {"mode": "preview", "reason": "device arm failed", "halt": True}
