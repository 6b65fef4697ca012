"""The execute gate's states and refusals, and the session loop's controls: typed, queued to the loop thread
(never carried out on the caller's), in the order they arrive."""

from __future__ import annotations

import threading

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
