"""One operator, two sides, from one VMC sender: a bimanual rig whose four devices (a vmc.glove and a vmc.suit
per side, `side` choosing the bones) share one UDP port on loopback. Real OSC frames of a symmetric operator
drive a recorded BimanualSession: both sides' pipelines step from their own hand and wrist, and the left
side's targets are the mirror of the right's (the left robot mirrors the right joint for joint)."""

from __future__ import annotations

import numpy as np

from teleprev.live.record.bimanual_session import open_session
from teleprev.live.record.session import RecordOptions
from teleprev.session.reader import SessionReader
from tests.helpers.ports import free_port
from tests.helpers.vmc import VmcSender
from tests.helpers.wait import wait_until


def rig_text(port: int) -> str:
    sides = "".join(
        f'[sides.{side}]\narm = "arm_{side}"\nhand = "hand_{side}"\nglove = "glove_{side}"\nsuit = "suit_{side}"\n'
        f'mount_xyz = [0.0, {0.3 if side == "left" else -0.3}, 0.0]\n\n'
        f'[devices.glove_{side}]\nplugin = "vmc.glove"\nport = {port}\nside = "{side}"\n\n'
        f'[devices.suit_{side}]\nplugin = "vmc.suit"\nport = {port}\nside = "{side}"\n\n'
        f'[devices.arm_{side}]\nplugin = "sim.arm"\n\n[devices.hand_{side}]\nplugin = "sim.hand"\n\n'
        for side in ("left", "right"))
    return f'[rig]\nname = "vmc_bimanual"\n\n[pipeline]\ntcp_link = "palm_lower"\n\n{sides}'


def test_one_vmc_sender_drives_both_sides_of_a_session(tmp_path):
    port = free_port()
    rig = tmp_path / "rig.toml"
    rig.write_text(rig_text(port))
    rec = open_session(RecordOptions(rig=rig, out=tmp_path / "s.mcap"))
    sender = VmcSender(port, both_sides=True)
    rec.start()
    try:
        sender.start(rate_hz=60.0)

        def stepped():
            views = rec.loop.snapshot.sides
            return len(views) == 2 and all(v.step is not None and v.step.corrected is not None for v in views)
        wait_until(stepped, 30, what="both sides stepped from the VMC frames")
        def left_frames():
            counter = rec.loop.stats.streams.get("/glove/glove_left/hand")
            return counter is not None and counter.count >= 30
        wait_until(left_frames, 30, what="30 left-hand frames")
    finally:
        sender.stop()
        rec.stop()
    with SessionReader(tmp_path / "s.mcap") as r:
        topics = set(r.topics) if hasattr(r, "topics") else {m.topic for m in r.messages()}
        corrected = {side: [m.payload for m in r.messages(topics=[f"/pipeline/{side}/corrected"])]
                     for side in ("left", "right")}
    assert {"/glove/glove_left/hand", "/glove/glove_right/hand", "/suit/suit_left/wrist",
            "/suit/suit_right/wrist"} <= topics
    assert len(corrected["left"]) >= 10 and len(corrected["right"]) >= 10
    # the same fingers on both hands: the left LEAP Hand takes the right one's joint angles
    left, right = corrected["left"][-1], corrected["right"][-1]
    assert np.abs(np.asarray(right.positions)).max() > 0.1
    np.testing.assert_allclose(left.positions, right.positions, atol=0.05)
