"""A rig of emulated hardware driven by the real SDKs, end to end: xarm.arm (xarm-python-sdk) and leap.hand
(dynamixel-sdk) against their emulators, the VMC glove and suit over loopback UDP and a camera over HTTP
MJPEG record a session (a collision on the arm sends it back to preview), which then exports to LeRobot,
replays to the emulated arm and passes the audit."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

from teleprev import topics
from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.emulators.mjpeg_stream import MjpegServer
from teleprev.emulators.xarm_controller import XArmController
from teleprev.session.reader import SessionReader
from tests.helpers.vmc import VmcSender, free_port

CLI = [sys.executable, "-m", "teleprev.cli.app"]
ENV = {**os.environ, "COLUMNS": "200"}


def wait_for(done, timeout_s):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not done():
        time.sleep(0.05)
    return done()


def test_an_emulated_rig_records_exports_replays_to_the_arm_and_audits(tmp_path):
    box, bus, cam = XArmController(host=None).start(), DynamixelBus().start(), MjpegServer(fps=30.0).start()
    port = free_port()
    sender = VmcSender(port).start(rate_hz=60.0)
    rig = tmp_path / "rig.toml"
    rig.write_text(f'[rig]\nname = "emulated"\n\n[devices.glove]\nplugin = "vmc.glove"\nport = {port}\n\n'
                   f'[devices.suit]\nplugin = "vmc.suit"\nport = {port}\n\n'
                   + box.rig_keys("arm") + "\n" + bus.rig_keys("hand") + "\n" + cam.rig_keys("cam_front"))
    out = tmp_path / "s.mcap"
    try:
        record = subprocess.Popen([*CLI, "record", str(rig), "--out", str(out), "--duration", "9", "--engage-after",
                                   "1", "--no-preview"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                  env=ENV)
        assert wait_for(lambda: len(box.commands) > 150, 60), "the arm was never commanded"
        assert bus.goal_writes > 100
        box.inject("collision")  # mid-episode, in execute
        time.sleep(0.5)
        commanded = len(box.commands)
        box.operator_clear()
        said, _ = record.communicate(timeout=90)
        assert len(box.commands) == commanded  # nothing moved the arm after the stop, until the end
    finally:
        sender.stop()
        cam.stop()
    said = " ".join(said.split())
    assert record.returncode == 1, said  # a device failed
    assert "controller error 31: Collision Caused Abnormal Current" in said, said

    reader = SessionReader(out)
    modes = [m.payload.data for m in reader.messages([topics.MODE])]
    assert {"mode": "preview", "reason": "device arm failed"} in modes, modes  # back in preview
    assert reader.topics["/camera/cam_front/image"].message_count > 100
    assert reader.topics["/hand/hand/state"].message_count > 300 and reader.topics["/arm/arm/state"].message_count > 300

    export = subprocess.Popen([*CLI, "export", str(out), "--repo-id", "lab/emulated", "--root", str(tmp_path / "ds")],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=ENV)
    try:
        audit = subprocess.run([*CLI, "audit", str(out)], capture_output=True, text=True, env=ENV, timeout=120)
        assert audit.returncode == 0, audit.stdout + audit.stderr
        before = len(box.commands), bus.goal_writes
        replay = subprocess.run([*CLI, "replay", str(out), "--to", "arm", "--rig", str(rig), "--no-preview",
                                 "--engage-after", "0.1"], capture_output=True, text=True, env=ENV, timeout=120)
        assert replay.returncode == 0, replay.stdout + replay.stderr
        assert len(box.commands) > before[0] + 100 and bus.goal_writes > before[1] + 100  # played to the robot
        assert [f for f in box.faults if f[2] != 31] == []  # within the controller's limits all along
    finally:
        exported, _ = export.communicate(timeout=180)
        box.stop()
        bus.stop()
    assert export.returncode == 0, exported
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    assert info["total_episodes"] >= 1 and info["total_frames"] > 30
    assert "observation.images.cam_front" in info["features"] and info["features"]["action"]["shape"] == [22]
