"""An emulated bimanual rig: two xArm controller emulators and two Dynamixel buses, each side's arm and hand
driven through the real xArm and LEAP plugins and their SDKs, from paced processes of their own, by one
simulated operator. Each side's commands are written on its own wire and arrive at its own controller."""

from __future__ import annotations

from pathlib import Path

from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.emulators.xarm_controller import XArmController
from teleprev.live.record.bimanual_session import BimanualSession
from teleprev.live.record.session import RecordOptions
from teleprev.session.reader import SessionReader
from tests.helpers.emulated_rig import EmulatorProcess, _section, box_summary, bus_summary
from tests.helpers.wait import wait_until

ROOT = Path(__file__).resolve().parents[2]
SIDES = ("left", "right")


def test_two_emulated_arms_and_hands_driven_through_their_sdks(tmp_path):
    boxes = {side: EmulatorProcess(lambda: XArmController(host=None), f"arm_{side}", box_summary) for side in SIDES}
    buses = {side: EmulatorProcess(DynamixelBus, f"hand_{side}", bus_summary) for side in SIDES}
    text = (ROOT / "rigs" / "sim_bimanual.toml").read_text()
    for side in SIDES:
        text = _section(_section(text, f"devices.arm_{side}", boxes[side].keys), f"devices.hand_{side}",
                        buses[side].keys)
    rig = tmp_path / "rig.toml"
    rig.write_text(text)
    out = tmp_path / "s.mcap"
    try:
        with BimanualSession(RecordOptions(out=out, rig=rig, connect_timeout_s=30)) as rec:
            assert sorted(rec.hosts) == ["left/arm", "left/hand", "right/arm", "right/hand"]
            assert rec.wait_connected() == []
            rec.loop.start_episode()
            wait_until(lambda: rec.loop.snapshot.step is not None, 30, what="a pipeline step")
            rec.loop.engage()
            sent = rec.loop.stats.commands_sent
            wait_until(lambda: min(sent[f"{s}/{k}"] for s in SIDES for k in ("arm", "hand")) > 100, 60,
                       what="commands written on both sides")
            rec.loop.to_preview()
            assert rec.settle(5.0)
            pids = {key: host.pid for key, host in rec.hosts.items()}
    finally:
        arms = {side: box.finish() for side, box in boxes.items()}
        hands = {side: bus.finish() for side, bus in buses.items()}
    assert len(set(pids.values())) == 4  # a paced process per actuator
    with SessionReader(out) as reader:
        assert set(reader.metadata["actuator_processes"]) == {"left/arm", "left/hand", "right/arm", "right/hand"}
        for side in SIDES:
            wired = [m.payload.data for m in reader.messages([f"/command/{side}/wire"])]
            for kind in ("arm", "hand"):
                commanded = [m.payload.stamp_ns for m in reader.messages([f"/command/{side}/{kind}"])]
                written = [w["t_ns"] for w in wired if w["kind"] == kind]
                assert len(commanded) > 100 and written == commanded, (side, kind, len(commanded), len(written))
            arm_writes = [w for w in wired if w["kind"] == "arm"]
            assert all(w["sent"] for w in arm_writes)
            # each side's controller received its side's commands, and faulted on none
            assert arms[side]["commands"] == len(arm_writes) and arms[side]["faults"] == []
            assert hands[side]["goal_writes"] >= sum(1 for w in wired if w["kind"] == "hand" and w["sent"]) > 100
