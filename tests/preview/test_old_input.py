"""Input that reaches the step old says so on the record screen: a VMC frame over loopback UDP that arrives
600 ms after its sender time (a frame held up on a busy machine) is stepped, the session loop's snapshot
carries its age, and the preview prints it, in red once past the pipeline's stale limit; fresh input
prints nothing."""

from __future__ import annotations

import io
import time

from rich.console import Console

from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.preview.dashboard import episode_line
from teleprev.status import LoopSnapshot
from tests.helpers.ports import free_port
from tests.helpers.sessions import wait_opened
from tests.helpers.vmc import VmcSender, arm_messages, bundle, finger_messages, rig_text
from tests.helpers.wait import wait_until

GLOVE = "/glove/glove/hand"


def shown(snap: LoopSnapshot) -> str:
    console = Console(file=io.StringIO(), width=120, record=True)
    console.print(episode_line(snap, snap.session_started_ns))
    return console.export_text()


def test_a_frame_stepped_600_ms_after_its_sender_time_is_shown_as_old_input(tmp_path):
    port = free_port()
    rig = tmp_path / "vmc.toml"
    rig.write_text(rig_text(port))
    sender = VmcSender(port)
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap", rig=rig))
    rec.start()
    try:
        wait_opened(rec)

        def frame(sender_time: float) -> bytes:
            return bundle(*arm_messages(t=sender_time), *finger_messages(0.5)).dgram

        for _ in range(20):  # on time: the clock sync locks onto the sender's clock
            sender.send(frame(time.monotonic()))
            time.sleep(1 / 60)
        sender.send(frame(time.monotonic() - 0.6))
        wait_until(lambda: rec.runners["glove"].stats().topics.get(GLOVE) == 21, what="every frame received")
        wait_until(lambda: rec.loop.backlog() == 0 and rec.loop.snapshot.input_age_ms >= 590, 5.0,
                   what="the late frame stepped")
        snap = rec.loop.snapshot
    finally:
        rec.stop()
        sender.stop()
    assert snap.stale_ms == 150.0 and snap.input_old
    text = shown(snap)
    assert f"input {snap.input_age_ms:.0f} ms old when stepped (stale: the robot holds)" in text


def test_fresh_input_shows_nothing_and_old_input_below_the_stale_limit_says_where_it_holds():
    fresh = LoopSnapshot(session_started_ns=0, input_age_ms=8.0, stale_ms=150.0)
    assert not fresh.input_old and "input" not in shown(fresh)
    old = LoopSnapshot(session_started_ns=0, input_age_ms=70.0, stale_ms=150.0)
    assert old.input_old
    assert "input 70 ms old when stepped (the robot holds at 150 ms)" in shown(old)
    assert not LoopSnapshot(input_age_ms=500.0).input_old  # no pipeline, no stale limit: nothing to say
