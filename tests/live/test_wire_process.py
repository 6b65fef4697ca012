"""The real arm's and hand's commands leave on the wire from paced processes, never from a thread of the
session process: a recording with the emulated xArm controller and Dynamixel bus (the real SDKs), driven by
the simulated operator, engages, and every SDK write of a command is made in a SCHED_FIFO process other
than the session's, one per actuator. What went out is recorded: each written command on /command/wire,
matching the ticks' commands on /command/arm and /command/hand."""

from __future__ import annotations

import os

from teleprev import topics
from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.emulators.xarm_controller import XArmController
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from teleprev_devices.leap import LeapHand
from teleprev_devices.xarm import XArm
from tests.helpers.emulated_rig import sim_operator_rig
from tests.helpers.wait import wait_until


def note_writer(cls, log):
    """Wrap the plugin's SDK write so that every command written notes its process and scheduling policy."""
    write = cls._write

    def noted(self, target):
        with open(log, "a") as f:
            f.write(f"{type(self).__name__} {os.getpid()} {os.sched_getscheduler(0)}\n")
        return write(self, target)

    return noted


def test_commands_are_written_from_paced_processes_not_the_session(tmp_path, monkeypatch):
    log = tmp_path / "writes.txt"
    monkeypatch.setattr(XArm, "_write", note_writer(XArm, log))
    monkeypatch.setattr(LeapHand, "_write", note_writer(LeapHand, log))
    box, bus = XArmController(host=None).start(), DynamixelBus().start()
    out, rig = tmp_path / "s.mcap", tmp_path / "rig.toml"
    rig.write_text(sim_operator_rig(box.rig_keys("arm"), bus.rig_keys("hand"), camera=False))  # no camera: less load
    try:
        with LiveSession(RecordOptions(out=out, rig=rig, connect_timeout_s=20)) as rec:
            assert rec.wait_connected() == []
            rec.loop.start_episode()
            wait_until(lambda: rec.loop.snapshot.step is not None, 20, what="a pipeline step")
            rec.loop.engage()
            wait_until(lambda: len(box.commands) > 120 and bus.goal_writes > 120, 30, what="commands at the emulators")
            rec.loop.to_preview()
            assert rec.settle(5.0)
            arm_pid, hand_pid = rec.hosts["arm"].pid, rec.hosts["hand"].pid
    finally:
        box.stop()
        bus.stop()

    writes = [line.split() for line in log.read_text().splitlines()]
    by_plugin = {name: {(int(pid), int(policy)) for n, pid, policy in writes if n == name} for name in ("XArm", "LeapHand")}
    assert by_plugin["XArm"] == {(arm_pid, os.SCHED_FIFO)}, by_plugin
    assert by_plugin["LeapHand"] == {(hand_pid, os.SCHED_FIFO)}, by_plugin
    assert os.getpid() not in (arm_pid, hand_pid) and arm_pid != hand_pid

    reader = SessionReader(out)
    wired = [m.payload for m in reader.messages([topics.COMMAND_WIRE])]
    for kind, topic in (("arm", topics.COMMAND_ARM), ("hand", topics.COMMAND_HAND)):
        commanded = [m.payload.stamp_ns for m in reader.messages([topic])]
        written = [w.data["t_ns"] for w in wired if w.data["kind"] == kind]
        assert len(commanded) > 120 and written == commanded, (kind, len(commanded), len(written))
        assert all(w.data["sent"] for w in wired if w.data["kind"] == kind)
        # the write began when the tick was sampled, give or take the hop between two paced processes
        assert max(w.stamp_ns - w.data["t_ns"] for w in wired if w.data["kind"] == kind) < 50_000_000
    assert len(box.commands) == sum(1 for w in wired if w.data["kind"] == "arm")
