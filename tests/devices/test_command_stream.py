"""The tests' command stream must stay inside the servo rule even when its thread is preempted: each
position belongs to its own stamp, and a stall past the rule's stream gap starts again from rest."""

from __future__ import annotations

import threading
import time

import numpy as np

from teleprev.devices.servo_limits import ServoStreamRule
from tests.helpers.hardware import CommandStream
from tests.helpers.wait import wait_until


class StallingClock:
    """A session clock whose readings are delayed now and then, as a preempted thread's are: 15 ms every
    5th reading and 90 ms (past the rule's 60 ms stream gap) every 23rd."""

    def __init__(self):
        self.readings = 0

    def now_ns(self) -> int:
        self.readings += 1
        if self.readings % 23 == 0:
            time.sleep(0.090)
        elif self.readings % 5 == 0:
            time.sleep(0.015)
        return time.monotonic_ns()


class JudgedArm:
    """An actuator that judges every command by the servo rule, as the sim arm and the xArm plugin do."""

    joint_names = tuple(f"joint{i}" for i in range(1, 7))

    def __init__(self):
        self._target = np.zeros(6)
        self.rule = ServoStreamRule(self.joint_names, max_acceleration=10.0, max_jerk=500.0, period_ns=10_000_000)
        self.broken = []
        self.lock = threading.Lock()

    def send(self, sample) -> None:
        with self.lock:
            broken = self.rule.check(sample.stamp_ns, np.asarray(sample.positions),
                                     lambda: (self._target.copy(), np.zeros(6)))
            if broken is not None:
                self.broken.append(broken.describe())
            self._target = np.asarray(sample.positions, dtype=float)


def test_a_stream_whose_clock_stalls_stays_inside_the_servo_rule():
    arm, clock = JudgedArm(), StallingClock()
    stream = CommandStream(arm, clock, rate_hz=100.0, amplitude=0.05, period_s=1.0).start()
    try:
        wait_until(lambda: stream.sent >= 120, 20.0, what="120 commands sent", poll_s=0.05)
    finally:
        stream.stop()
    assert clock.readings >= 46, "the clock never stalled past the stream gap"
    assert arm.broken == []


class MonotonicClock:
    def now_ns(self) -> int:
        return time.monotonic_ns()


class FaultingArm(JudgedArm):
    """Refuses every 7th command, as a device does after a fault: the stream starts again from its target."""

    def __init__(self):
        super().__init__()
        self.sends = 0
        self.seen: list[np.ndarray] = []

    def send(self, sample) -> None:
        self.sends += 1
        if self.sends % 7 == 0:
            from teleprev.errors import DeviceError

            raise DeviceError("refused", "faulting arm")
        super().send(sample)
        self.seen.append(np.asarray(sample.positions, dtype=float))


def test_a_stream_that_starts_again_swings_back_instead_of_creeping():
    """Started again where its last swing left it, the stream swings back to where it began, never past it:
    it stays within [start, start + 2 x amplitude] (always swinging up, it crept into a joint limit under load;
    swinging down by as much, it passed a hand's joint limit that it began next to)."""
    arm = FaultingArm()
    stream = CommandStream(arm, MonotonicClock(), rate_hz=200.0, amplitude=0.05, period_s=0.1).start()
    try:
        wait_until(lambda: stream.failed >= 30, 20.0, what="30 restarts", poll_s=0.05)
    finally:
        stream.stop()
    moved = np.array(arm.seen)[:, 0]
    assert moved.max() <= 2 * 0.05 + 1e-9 and moved.min() >= -1e-9, (moved.min(), moved.max())
