"""Resuming after a loss of the operator's input is the operator's decision past the rig's bound (issue 37
item 3): a VMC glove and suit (real OSC bundles on loopback UDP) go silent or send junk while executing."""

from __future__ import annotations

import math
import signal
import time

import numpy as np

from teleprev import topics
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from tests.helpers.faults import has_traceback, start_cli, wait_for_file
from tests.helpers.ports import free_port
from tests.helpers.sessions import wait_opened
from tests.helpers.vmc import VmcSender, arm_messages, bundle, finger_messages, rig_text
from tests.helpers.wait import wait_until


class LossySender(VmcSender):
    """A VMC sender whose frames can stop ("silent") or turn to junk ("nan": every value not a number)."""

    loss = ""

    def frame(self, k: int, rate_hz: float) -> bytes:
        if self.loss == "nan":
            arm = arm_messages(root_pos=(math.nan,) * 3, t=100.0 + k / rate_hz)
            return bundle(*arm, *finger_messages(math.nan)).dgram
        return super().frame(k, rate_hz)

    def send(self, datagram: bytes) -> None:
        if self.loss != "silent":
            super().send(datagram)


def executing_session(tmp_path, sender: LossySender, bound_s: float = 1.0) -> LiveSession:
    rig = tmp_path / "vmc.toml"
    rig.write_text(rig_text(sender.address[1]) + f"\n[session]\ninput_loss_to_preview_s = {bound_s}\n")
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap", rig=rig))
    rec.start()
    wait_opened(rec)
    sender.start(rate_hz=60.0)
    assert rec.wait_connected(5.0) == []

    engage_by_key(rec)
    return rec


def engage_by_key(rec: LiveSession) -> None:
    def engaged():
        if rec.loop.snapshot.mode != "execute":
            rec.loop.engage("key")  # refused until the inputs are fresh: ask again
        return rec.loop.snapshot.mode == "execute"

    wait_until(engaged, 10.0, what="the operator engages", poll_s=0.1)


def operator_events(path) -> list[dict]:
    return [m.payload.data for m in SessionReader(path).messages([topics.OPERATOR])]


def test_a_short_loss_resumes_from_the_held_command_at_the_engage_speed(tmp_path):
    sender = LossySender(free_port())
    rec = executing_session(tmp_path, sender)
    try:
        wait_until(lambda: rec.loop.stats.ticks > 120, 10.0, what="a second of commands")
        sender.loss = "silent"
        time.sleep(0.4)  # the loss: well within the bound
        sender.loss = ""
        ticks = rec.loop.stats.ticks
        wait_until(lambda: rec.loop.stats.ticks > ticks + 120, 10.0, what="a second of commands after the loss")
        assert rec.loop.snapshot.mode == "execute", rec.loop.snapshot.message
    finally:
        sender.stop()
        rec.stop()
    path = tmp_path / "s.mcap"
    reader = SessionReader(path)
    modes = [m.payload.data for m in reader.messages([topics.MODE])]
    assert [m["mode"] for m in modes][:1] == ["execute"] and not [m for m in modes if m["reason"] == "input_lost"]
    events = [e["event"] for e in operator_events(path)]
    assert "input_held" in events and "input_resumed" in events, events
    ticks = [(m.payload.stamp_ns, m.payload.data["flags"]) for m in reader.messages([topics.COMMAND_TICK])]
    resumed = [i for i, (_, flags) in enumerate(ticks) if "input_resumed" in flags]
    assert resumed, "the planner never resumed from a loss"
    # from the held commands, at the engage fraction of the speed caps until they meet the targets
    ramp = [stamp for stamp, flags in ticks[resumed[0]:] if "engaging" in flags]
    assert ramp and "engaging" in ticks[resumed[0]][1]
    hand = {m.payload.stamp_ns: m.payload.velocities for m in reader.messages([topics.COMMAND_HAND])}
    speeds = [np.abs(hand[stamp]).max() for stamp in ramp if stamp in hand]
    cfg = rec.rig.pipeline
    assert speeds and max(speeds) <= cfg.engage_speed_frac * cfg.hand_speed + 1e-9, max(speeds)


def _lose_past_the_bound(tmp_path, loss: str):
    sender = LossySender(free_port())
    rec = executing_session(tmp_path, sender)
    try:
        wait_until(lambda: rec.loop.stats.ticks > 120, 10.0, what="a second of commands")
        sender.loss = loss
        wait_until(lambda: rec.loop.snapshot.mode == "preview", 3.0, what="back to preview after the bound")
        shown = rec.loop.snapshot
        sender.loss = ""  # the input is back: nothing moves until the operator engages
        wait_until(lambda: not rec.loop.relay.active, 3.0, what="the robot at rest")
        rec.loop.engage(unattended=True)  # a script's engage is refused after the loss
        wait_until(lambda: rec.loop.snapshot.message.startswith("cannot switch to execute"), 3.0, what="the refusal")
        assert rec.loop.snapshot.mode == "preview"
        engage_by_key(rec)  # the operator's is let through
    finally:
        sender.stop()
        rec.stop()
    assert "back in PREVIEW" in shown.message and shown.fault, shown
    path = tmp_path / "s.mcap"
    modes = [(m.payload.data["mode"], m.payload.data["reason"]) for m in SessionReader(path).messages([topics.MODE])]
    assert modes[:3] == [("execute", "key"), ("preview", "input_lost"), ("execute", "key")], modes
    lost = [e for e in operator_events(path) if e["event"] == "input_lost"]
    assert len(lost) == 1 and "more than 1 s" in lost[0]["detail"], lost
    return path


def test_silence_past_the_bound_goes_back_to_preview_until_the_operator_engages(tmp_path):
    _lose_past_the_bound(tmp_path, "silent")


def test_junk_past_the_bound_goes_back_to_preview_until_the_operator_engages(tmp_path):
    _lose_past_the_bound(tmp_path, "nan")


def test_a_frozen_record_process_goes_back_to_preview_and_sends_nothing_more(tmp_path):
    """SIGSTOP / SIGCONT of `teleprev record` for 2 s while executing: the session says it was frozen,
    goes back to preview, and the commands brake to rest (before: they resumed at the speed caps)."""
    out = tmp_path / "s.mcap"
    proc = start_cli(["record", "--duration", "7", "--no-preview", "--engage-after", "0.3", "-o", out])
    try:
        wait_for_file(out, 150_000, timeout=60)
        time.sleep(1.5)  # executing by now (the engage came 0.3 s in)
        proc.send_signal(signal.SIGSTOP)
        time.sleep(2.0)
        proc.send_signal(signal.SIGCONT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not has_traceback(stdout + stderr), stderr
    reader = SessionReader(out)
    modes = [(m.log_time_ns, m.payload.data["mode"], m.payload.data["reason"]) for m in reader.messages([topics.MODE])]
    lost_at = next(t for t, mode, reason in modes if reason == "input_lost")
    engages = [t for t, mode, _ in modes if mode == "execute"]
    assert engages and not [t for t in engages if t > lost_at], modes
    lost = [e for e in operator_events(out) if e["event"] == "input_lost"]
    assert len(lost) == 1 and "did not run for" in lost[0]["detail"], lost
    after = [m.log_time_ns for m in reader.messages([topics.COMMAND_ARM]) if m.log_time_ns > lost_at + 1e9]
    assert after == [], "commands went on after the switch to preview"
