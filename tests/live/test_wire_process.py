"""The real arm's and hand's commands leave on the wire from paced processes, never from a thread of the
session process: a recording with the emulated xArm controller and Dynamixel bus (the real SDKs), driven by
the simulated operator, engages, and every SDK write of a command is made in a SCHED_FIFO process other
than the session's, one per actuator. What went out is recorded: each written command on /command/wire,
matching the ticks' commands on /command/arm and /command/hand, and each arrived at the controller. An
actuator's process that dies is the device's fault: the session goes back to preview and refuses a
script's engage."""

from __future__ import annotations

import os
import signal
import threading
import time

from teleprev import topics
from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.emulators.xarm_controller import XArmController
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from teleprev_devices.leap import LeapHand
from teleprev_devices.xarm import XArm
from tests.helpers.emulated_rig import EmulatorProcess, box_summary, bus_summary, sim_operator_rig
from tests.helpers.wait import wait_until


def note_writer(cls, log):
    """Wrap the plugin's SDK write so that every command written notes its process and scheduling policy."""
    write = cls._write

    def noted(self, target):
        with open(log, "a") as f:
            f.write(f"{type(self).__name__} {os.getpid()} {os.sched_getscheduler(0)}\n")
        return write(self, target)

    return noted


def emulated(tmp_path):
    """The emulated arm and hand (in processes of their own: hardware outside this machine) and their rig."""
    box = EmulatorProcess(lambda: XArmController(host=None), "arm", box_summary)
    bus = EmulatorProcess(DynamixelBus, "hand", bus_summary)
    rig = tmp_path / "rig.toml"
    rig.write_text(sim_operator_rig(box.keys, bus.keys, camera=False))  # no camera: less load
    return box, bus, rig


def test_commands_are_written_from_paced_processes_not_the_session(tmp_path, monkeypatch):
    log = tmp_path / "writes.txt"
    monkeypatch.setattr(XArm, "_write", note_writer(XArm, log))
    monkeypatch.setattr(LeapHand, "_write", note_writer(LeapHand, log))
    box, bus, rig = emulated(tmp_path)
    out = tmp_path / "s.mcap"
    try:
        with LiveSession(RecordOptions(out=out, rig=rig, connect_timeout_s=20)) as rec:
            assert rec.wait_connected() == []
            rec.loop.start_episode()
            wait_until(lambda: rec.loop.snapshot.step is not None, 20, what="a pipeline step")
            rec.loop.engage()
            sent = rec.loop.stats.commands_sent
            wait_until(lambda: sent["arm"] > 120 and sent["hand"] > 120, 30, what="commands written")
            rec.loop.to_preview()
            assert rec.settle(5.0)
            pids = {kind: host.pid for kind, host in rec.hosts.items()}
    finally:
        arm, hand = box.finish(), bus.finish()

    writes = [line.split() for line in log.read_text().splitlines()]
    by_plugin = {name: {(int(pid), int(policy)) for n, pid, policy in writes if n == name}
                 for name in ("XArm", "LeapHand")}
    assert all(pid != os.getpid() for p in by_plugin.values() for pid, _ in p), f"written by the session: {by_plugin}"
    assert by_plugin["XArm"] == {(pids["arm"], os.SCHED_FIFO)}, by_plugin
    assert by_plugin["LeapHand"] == {(pids["hand"], os.SCHED_FIFO)}, by_plugin
    assert pids["arm"] != pids["hand"]

    reader = SessionReader(out)
    assert reader.metadata["actuator_processes"] == {"arm": "SCHED_FIFO priority 49", "hand": "SCHED_FIFO priority 49"}
    wired = [m.payload for m in reader.messages([topics.COMMAND_WIRE])]
    for kind, topic in (("arm", topics.COMMAND_ARM), ("hand", topics.COMMAND_HAND)):
        commanded = [m.payload.stamp_ns for m in reader.messages([topic])]
        written = [w.data["t_ns"] for w in wired if w.data["kind"] == kind]
        assert len(commanded) > 120 and written == commanded, (kind, len(commanded), len(written))
        # each written, or (a hand's write that waited for its bus) superseded by a later one, never in a burst
        assert all(w.data["sent"] or w.data["error"].startswith("superseded") for w in wired if w.data["kind"] == kind)
    assert all(w.data["sent"] for w in wired if w.data["kind"] == "arm")
    # the arm's write began when the tick was sampled, give or take the hop between two paced processes (the
    # hand's waits for a read in progress on its bus: tens of ms when a reply is missed)
    assert max(w.stamp_ns - w.data["t_ns"] for w in wired if w.data["kind"] == "arm") < 50_000_000
    assert arm["commands"] == sum(1 for w in wired if w.data["kind"] == "arm") and arm["faults"] == []
    assert hand["goal_writes"] >= sum(1 for w in wired if w.data["kind"] == "hand" and w.data["sent"])


def test_an_actuator_process_that_dies_is_a_device_fault_and_execute_stays_refused(tmp_path):
    box, bus, rig = emulated(tmp_path)
    out = tmp_path / "s.mcap"
    try:
        with LiveSession(RecordOptions(out=out, rig=rig, connect_timeout_s=20)) as rec:
            assert rec.wait_connected() == []
            wait_until(lambda: rec.loop.snapshot.step is not None, 20, what="a pipeline step")
            rec.loop.engage()
            wait_until(lambda: rec.loop.stats.commands_sent["arm"] > 30, 30, what="commands at the arm")
            os.kill(rec.hosts["arm"].pid, signal.SIGKILL)
            wait_until(lambda: rec.loop.snapshot.fault, 10, what="the fault shown to the operator")
            faulted_ns = time.monotonic_ns()
            assert rec.settle(5.0)
            rec.loop.engage(unattended=True)  # a script's engage after a fault is refused
            wait_until(lambda: "cannot switch to execute" in rec.loop.snapshot.message, 5, what="the refusal")
            assert rec.driver.mode == "preview" and rec.runners["arm"].stats().state == "error"
    finally:
        arm, _ = box.finish(), bus.finish()
    assert max(a[0] for a in arm["arrivals"]) < faulted_ns  # nothing reached the arm once it was seen gone
    reader = SessionReader(out)
    errors = [m.payload.data["message"] for m in reader.messages([topics.DEVICE_EVENT])
              if m.payload.data["event"] == "error" and m.payload.data["device"] == "arm"]
    assert len(errors) == 1 and "the actuator's process ended" in errors[0], errors
    modes = [m.payload.data for m in reader.messages([topics.MODE])]
    assert {"mode": "preview", "reason": "device arm failed", "halt": True} in modes, modes


def test_a_replay_to_the_arm_writes_from_paced_processes_not_the_player(tmp_path, monkeypatch):
    """`replay --to arm` hands the played commands to the same paced actuator processes a recording uses:
    no SDK write from the replay's process, and each write on the replay recording's /command/wire."""
    from teleprev.live.replay.playback import build_player

    log = tmp_path / "writes.txt"
    box, bus, rig = emulated(tmp_path)
    out, replayed = tmp_path / "s.mcap", tmp_path / "replayed.mcap"
    try:
        with LiveSession(RecordOptions(out=out, rig=rig, connect_timeout_s=20)) as rec:
            assert rec.wait_connected() == []
            rec.loop.start_episode()
            wait_until(lambda: rec.loop.snapshot.step is not None, 20, what="a pipeline step")
            rec.loop.engage()
            wait_until(lambda: rec.loop.stats.commands_sent["arm"] > 60, 30, what="commands written")
            rec.loop.to_preview()
            assert rec.settle(5.0)
        monkeypatch.setattr(XArm, "_write", note_writer(XArm, log))
        monkeypatch.setattr(LeapHand, "_write", note_writer(LeapHand, log))
        player, runners, _, _, _, recording = build_player(out, None, 1.0, "arm", rig, smoothed=True, out=replayed)
        pids = {kind: player.actuators[kind].pid for kind in ("arm", "hand")}
        for r in runners:
            r.start()
        thread = threading.Thread(target=player.run)
        thread.start()
        player.engage()
        thread.join(60)
        errors = {r.name: r.stats().last_error for r in runners if r.stats().last_error}
        for r in runners:
            r.stop()
        recording.close()
    finally:
        arm, _ = box.finish(), bus.finish()

    assert player.state.message == "", (player.state.message, errors)
    assert sum(1 for phase, _, _ in player.state.sent if phase == "playing") > 60
    writes = [line.split() for line in log.read_text().splitlines()]
    by_plugin = {name: {(int(pid), int(policy)) for n, pid, policy in writes if n == name}
                 for name in ("XArm", "LeapHand")}
    assert by_plugin["XArm"] == {(pids["arm"], os.SCHED_FIFO)}, by_plugin
    assert by_plugin["LeapHand"] == {(pids["hand"], os.SCHED_FIFO)}, by_plugin
    assert os.getpid() not in pids.values()
    reader = SessionReader(replayed)
    wired = [m.payload.data for m in reader.messages([topics.COMMAND_WIRE])]
    commanded = [m.payload.stamp_ns for m in reader.messages([topics.COMMAND_ARM])]
    assert [w["t_ns"] for w in wired if w["kind"] == "arm"] == commanded and all(w["sent"] for w in wired
                                                                               if w["kind"] == "arm")
    assert arm["faults"] == [] and len(arm["arrivals"]) >= len(commanded)
