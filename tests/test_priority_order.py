"""The real-time priorities of a session's processes, in the order the commands need: the paced sender, which
puts the targets on the wire, above every other process of ours; the actuators' processes, which write
them, next; then the physics world, the emulated hardware of the tests and benches, and the input's
decoding. A process above the sender would hold up a tick on a loaded 2-core machine (SCHED_FIFO: a
process runs until one of higher priority wants its core)."""

from __future__ import annotations

from teleprev.emulators.dynamixel_bus import REPLY_PRIORITY
from teleprev.thread_priority import ACTUATOR_PRIORITY, DEFAULT_PRIORITY, INPUT_PRIORITY, WORLD_PRIORITY
from tests.helpers.emulated_rig import EMULATOR_PRIORITY


def test_the_sender_first_then_the_writes_then_the_rest():
    assert DEFAULT_PRIORITY > ACTUATOR_PRIORITY > WORLD_PRIORITY > INPUT_PRIORITY >= 1
    assert ACTUATOR_PRIORITY > EMULATOR_PRIORITY >= REPLY_PRIORITY > INPUT_PRIORITY
    assert DEFAULT_PRIORITY < 99  # below the kernel's migration threads

