"""The bimanual sim rig with two emulated xArm controllers and two emulated Dynamixel buses in place of the
sim arms and hands (each emulator in a real-time process of its own, as tests/helpers/emulated_rig.py's):
one engaged stretch, recorded, and what the emulators saw. For tests/bimanual and bench/bimanual.py."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.emulators.xarm_controller import XArmController
from teleprev.live.record.bimanual_session import BimanualSession
from teleprev.live.record.session import RecordOptions
from tests.helpers.emulated_rig import EmulatorProcess, _section, box_summary, bus_summary
from tests.helpers.sessions import engage_until_accepted
from tests.helpers.wait import wait_until

ROOT = Path(__file__).resolve().parents[2]
SIDES = ("left", "right")


@dataclass
class EmulatedRun:
    session: Path
    hosts: list[str]  # "<side>/<kind>" of the actuators that ran in processes of their own
    pids: dict[str, int]
    settled: bool
    arms: dict[str, dict]  # per side, box_summary of its controller
    hands: dict[str, dict]  # per side, bus_summary of its bus


def run_emulated_bimanual(folder: Path, commands: int = 100, timeout_s: float = 60.0) -> EmulatedRun:
    """Record until each side's arm and hand took `commands` commands, then back to preview."""
    boxes = {side: EmulatorProcess(lambda: XArmController(host=None), f"arm_{side}", box_summary) for side in SIDES}
    buses = {side: EmulatorProcess(DynamixelBus, f"hand_{side}", bus_summary) for side in SIDES}
    text = (ROOT / "rigs" / "sim_bimanual.toml").read_text()
    for side in SIDES:
        text = _section(_section(text, f"devices.arm_{side}", boxes[side].keys), f"devices.hand_{side}",
                        buses[side].keys)
    rig = folder / "emulated_bimanual.toml"
    rig.write_text(text)
    out = folder / "emulated_bimanual.mcap"
    try:
        with BimanualSession(RecordOptions(out=out, rig=rig, connect_timeout_s=30)) as rec:
            hosts = sorted(rec.hosts)
            problems = rec.wait_connected()
            assert problems == [], problems
            rec.loop.start_episode()
            engage_until_accepted(rec, 30.0)  # (refused until both sides have previewed)
            sent = rec.loop.stats.commands_sent

            def written() -> bool:
                # On a loaded machine the input may stall past the rig's bound and send the session back to
                # preview; an operator engages again (this run's subject is the wire, not input loss).
                if rec.loop.driver.mode != "execute":
                    rec.loop.engage()
                return min(sent[f"{s}/{k}"] for s in SIDES for k in ("arm", "hand")) > commands

            wait_until(written, timeout_s, what="commands written on both sides", poll_s=0.1)
            rec.loop.to_preview()
            settled = rec.settle(5.0)
            pids = {key: host.pid for key, host in rec.hosts.items()}
    finally:
        arms = {side: box.finish() for side, box in boxes.items()}
        hands = {side: bus.finish() for side, bus in buses.items()}
    return EmulatedRun(out, hosts, pids, settled, arms, hands)


def check_emulated_run(run: EmulatedRun, commands: int = 100) -> list[str]:
    """What is wrong with an emulated run ([]: nothing): a process per actuator, each side's written commands
    equal to its recorded ones, each arm write received by its own controller, no controller fault."""
    from teleprev.session.reader import SessionReader

    wrong = []
    if run.hosts != ["left/arm", "left/hand", "right/arm", "right/hand"] or len(set(run.pids.values())) != 4:
        wrong.append(f"actuator processes: {run.pids}")
    if not run.settled:
        wrong.append("did not come to rest")
    with SessionReader(run.session) as reader:
        if set(reader.metadata.get("actuator_processes", {})) != set(run.hosts):
            wrong.append(f"actuator_processes record: {reader.metadata.get('actuator_processes')}")
        for side in SIDES:
            wired = [m.payload.data for m in reader.messages([f"/command/{side}/wire"])]
            for kind in ("arm", "hand"):
                commanded = [m.payload.stamp_ns for m in reader.messages([f"/command/{side}/{kind}"])]
                written = [w["t_ns"] for w in wired if w["kind"] == kind]
                if len(commanded) <= commands or written != commanded:
                    wrong.append(f"{side} {kind}: {len(commanded)} commanded, {len(written)} written")
            arm_writes = [w for w in wired if w["kind"] == "arm"]
            if not all(w["sent"] for w in arm_writes):
                wrong.append(f"{side} arm: writes not taken")
            if run.arms[side]["commands"] != len(arm_writes) or run.arms[side]["faults"]:
                wrong.append(f"{side} controller: {run.arms[side]['commands']} commands received of "
                             f"{len(arm_writes)} written, faults {run.arms[side]['faults']}")
            hand_sent = sum(1 for w in wired if w["kind"] == "hand" and w["sent"])
            if not run.hands[side]["goal_writes"] >= hand_sent > commands:
                wrong.append(f"{side} hand bus: {run.hands[side]['goal_writes']} goal writes, {hand_sent} sent")
    return wrong
