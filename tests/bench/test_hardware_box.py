"""bench/hardware.py's threaded xArm session against a control box in a process of its own (BoxProcess): the
box answers from there, not from a thread of the process that runs the plugin, and what the bench reads
of it (arrivals, targets run, faults, its judgement) and does to it (a fault, the operator's clear) goes
through that process. The plugin's side runs as in the product's actuator process: its runner's thread
and the SDK's own threads at the actuators' real-time priority (paced_runner)."""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.hardware import BoxProcess  # noqa: E402
from teleprev.clock import SessionClock  # noqa: E402
from teleprev.devices import DeviceContext  # noqa: E402
from teleprev.thread_priority import ACTUATOR_PRIORITY  # noqa: E402
from teleprev_devices.xarm import XArm, XArmSettings  # noqa: E402
from tests.helpers.hardware import CommandStream, EventLog, paced_runner  # noqa: E402
from tests.helpers.wait import wait_until  # noqa: E402


def _where(box) -> tuple[int, int]:
    return os.getpid(), os.sched_getscheduler(0)


def test_the_box_answers_from_its_own_process_and_is_read_there():
    box = BoxProcess()
    clock = SessionClock()
    arm = XArm("arm", XArmSettings(host=box.host), DeviceContext(clock))
    log = EventLog()
    before = {t.native_id for t in threading.enumerate()}
    runner = paced_runner(arm, log.sink, clock, reconnect_s=0.1)
    stream = None
    try:
        pid, policy = box.process.ask(_where)
        assert pid == box.process.proc.pid != os.getpid()
        if os.geteuid() == 0:  # where SCHED_FIFO is permitted, the box has it (tests/helpers/emulated_rig.py)
            assert policy == os.SCHED_FIFO
        assert log.wait(lambda: log.count("connected") == 1), log.events
        if os.geteuid() == 0:  # the runner's thread and the SDK's reply and report readers, all paced
            started = [t for t in threading.enumerate() if t.native_id not in before]
            assert len(started) >= 3, started
            assert {(t.name, os.sched_getscheduler(t.native_id), os.sched_getparam(t.native_id).sched_priority)
                    for t in started} == {(t.name, os.SCHED_FIFO, ACTUATOR_PRIORITY) for t in started}
        stream = CommandStream(arm, clock).start()
        wait_until(lambda: box.counts()[1] >= 50, 10.0, what="50 targets run by the box")
        stream.stop()
        arrived, ran = box.counts()
        arrivals = box.arrivals()
        assert len(arrivals) == arrived and ran == sum(a.taken for a in arrivals) == stream.sent
        assert len({tuple(np.round(a.target, 6)) for a in arrivals}) > 10  # the stream's moving targets
        assert [a.received_ns for a in box.arrivals(arrived - 3)] == [a.received_ns for a in arrivals[-3:]]
        found = box.findings()
        assert found.faults == [] and found.unknown == {} and len(found.judged) >= 40

        box.inject("collision")
        assert log.wait(lambda: log.count("error") == 1, 5.0), log.events
        assert "controller error 31" in log.of("error")[0]["message"]
        assert [what for _, what, _ in box.findings().faults] == ["collision detected"]
        box.operator_clear()
        assert log.wait(lambda: log.count("connected") == 2, 10.0), log.events  # back once cleared
    finally:
        if stream is not None:
            stream.stop()
        runner.stop()
        box.stop()
    assert not box.process.proc.is_alive()
