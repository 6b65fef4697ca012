"""A rig of emulated hardware driven by the real SDKs, end to end: xarm.arm (xarm-python-sdk) and leap.hand
(dynamixel-sdk) against their emulators, the VMC glove and suit over loopback UDP and a camera over HTTP
MJPEG record a session (a collision on the arm sends it back to preview), which then exports to LeRobot,
replays to the emulated arm and passes the audit. The emulators run in processes of their own, as hardware
runs outside the machine, so that a busy test process cannot starve their replies."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from teleprev import topics
from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.emulators.mjpeg_stream import MjpegServer
from teleprev.emulators.xarm_controller import XArmController
from teleprev.session.reader import SessionReader
from tests.helpers.emulated_rig import EmulatorProcess
from tests.helpers.ports import free_port
from tests.helpers.vmc import VmcSender, arm_messages, bundle, finger_messages
from tests.helpers.wait import WaitTimeout, wait_until

CLI = [sys.executable, "-m", "teleprev.cli.app"]
ENV = {**os.environ, "COLUMNS": "200"}


class StillHand(VmcSender):
    """The operator holds still: this test is about the hardware path (the moving glove's commands are
    audited in tests/evaluation)."""

    def frame(self, k: int, rate_hz: float) -> bytes:
        return bundle(*arm_messages(t=100.0 + k / rate_hz), *finger_messages(0.6)).dgram


def command_count(box) -> int:
    return len(box.commands)


def goal_writes(bus) -> int:
    return bus.goal_writes


def inject(box, what: str) -> None:
    box.inject(what)


def operator_clear(box) -> None:
    box.operator_clear()


def faults_but_collision(box) -> list:
    return [list(f) for f in box.faults if f[2] != 31]


def _summary(_emulator) -> dict:
    return {}


def test_an_emulated_rig_records_exports_replays_to_the_arm_and_audits(tmp_path):
    box = EmulatorProcess(lambda: XArmController(host=None), "arm", _summary)
    bus = EmulatorProcess(DynamixelBus, "hand", _summary)
    cam = MjpegServer(fps=30.0).start()
    port = free_port()
    sender = StillHand(port).start(rate_hz=60.0)
    rig = tmp_path / "rig.toml"
    rig.write_text(f'[rig]\nname = "emulated"\n\n[devices.glove]\nplugin = "vmc.glove"\nport = {port}\n\n'
                   f'[devices.suit]\nplugin = "vmc.suit"\nport = {port}\n\n'
                   + box.keys + "\n" + bus.keys + "\n" + cam.rig_keys("cam_front"))
    out = tmp_path / "s.mcap"
    record = None
    try:
        record = subprocess.Popen([*CLI, "record", str(rig), "--out", str(out), "--duration", "9", "--engage-after",
                                   "1", "--no-preview"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                  env=ENV)
        try:
            wait_until(lambda: box.ask(command_count) > 150, 60, what="150 arm commands", poll_s=0.05)
        except WaitTimeout:
            record.kill()
            raise AssertionError(
                f"the arm was commanded {box.ask(command_count)} times: {record.communicate()[0]}"
            ) from None
        assert bus.ask(goal_writes) > 50
        box.ask(inject, "collision")  # mid-episode, in execute
        commanded = box.ask(command_count)
        said, _ = record.communicate(timeout=90)
        # nothing is sent to the stopped arm: the operator has not cleared it
        assert box.ask(command_count) == commanded
        box.ask(operator_clear)
    finally:
        if record is not None and record.poll() is None:
            record.kill()
        sender.stop()
        cam.stop()
    said = " ".join(said.split())
    assert record.returncode == 1, said  # a device failed
    assert "controller error 31: Collision Caused Abnormal Current" in said, said

    reader = SessionReader(out)
    modes = [m.payload.data for m in reader.messages([topics.MODE])]
    # back in preview, nothing more sent to the stopped arm (halt), once
    assert modes.count({"mode": "preview", "reason": "device arm failed", "halt": True}) == 1, modes
    assert reader.topics["/camera/cam_front/image"].message_count > 100
    # (the stopped arm reports nothing until the operator clears it: its state ends at the collision)
    assert reader.topics["/hand/hand/state"].message_count > 300 and reader.topics["/arm/arm/state"].message_count > 150

    try:
        audit = subprocess.run([*CLI, "audit", str(out)], capture_output=True, text=True, env=ENV, timeout=120)
        assert audit.returncode == 0, audit.stdout + audit.stderr
        before = box.ask(command_count), bus.ask(goal_writes)
        replay = subprocess.run([*CLI, "replay", str(out), "--to", "arm", "--rig", str(rig), "--no-preview",
                                 "--engage-after", "2"], capture_output=True, text=True, env=ENV, timeout=120)
        assert replay.returncode == 0, replay.stdout + replay.stderr
        assert box.ask(command_count) > before[0] + 100 and bus.ask(goal_writes) > before[1] + 100  # played
        assert box.ask(faults_but_collision) == []  # within the controller's limits all along
    finally:
        box.finish()
        bus.finish()
    # (after the replay, not beside it: the emulated bus answers only as fast as this 2-core machine lets it)
    export = subprocess.run([*CLI, "export", str(out), "--repo-id", "lab/emulated", "--root", str(tmp_path / "ds")],
                            capture_output=True, text=True, env=ENV, timeout=300)
    assert export.returncode == 0, export.stdout + export.stderr
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    assert info["total_episodes"] >= 1 and info["total_frames"] > 30
    assert "observation.images.cam_front" in info["features"] and info["features"]["action"]["shape"] == [22]
