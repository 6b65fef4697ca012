"""A writer that falls behind is flagged, and what is already queued comes first: new work is shed, camera
frames before everything else, commands and events never (issue 37 item 2)."""

from __future__ import annotations

import json
import time

import numpy as np

from teleprev import topics
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.messages import Event, ImageSample, JointSample, Logged
from teleprev.session.reader import SessionReader
from teleprev.session.recorder import RECORDER_RECORD, Recorder
from tests.helpers.sessions import RIGS, wait_opened
from tests.helpers.wait import wait_until

CAMERA, GLOVE = "/camera/cam/image", "/glove/glove/hand"


def image(t: int) -> Logged:
    return Logged(CAMERA, t, ImageSample(t, "cam", b"\xff\xd8" + bytes(50_000)))


def glove(t: int) -> Logged:
    return Logged(GLOVE, t, JointSample(t, ("a",), np.array([0.1])))


def command(t: int) -> Logged:
    return Logged(topics.COMMAND_ARM, t, JointSample(t, ("j1",), np.array([0.2])))


def event(t: int) -> Logged:
    return Logged(topics.OPERATOR, t, Event(t, "teleprev.OperatorEvent", {"event": "note", "detail": ""}))


def test_a_stalled_writer_sheds_camera_frames_first_then_all_but_commands_and_events(tmp_path):
    told = []
    rec = Recorder(tmp_path / "s.mcap", lag_budget_s=0.2, on_behind=lambda *a: told.append(a))
    # The writer has not run yet: a writer starved of the CPU, as on a busy machine.
    t = 1
    for make in (image, glove, command, event):
        assert rec.log(make(t := t + 1))  # on time: everything is taken
    time.sleep(0.25)  # the oldest queued message is now older than the budget
    assert not rec.log(image(t := t + 1))
    assert rec.log(glove(t := t + 1)) and rec.log(command(t := t + 1)) and rec.log(event(t := t + 1))
    time.sleep(0.2)  # past twice the budget: only the commands and the events are taken
    assert not rec.log(image(t := t + 1)) and not rec.log(glove(t := t + 1))
    assert rec.log(command(t := t + 1)) and rec.log(event(t := t + 1))
    assert rec.lag_s > 0.4
    rec.start()
    wait_until(lambda: len(told) == 2, 5.0, what="behind, then caught up")
    assert rec.log(image(t := t + 1))  # caught up: camera frames are recorded again
    summary = rec.close()
    (behind, lag_s, _), (caught_up, _, shed) = told
    assert behind and lag_s > 0.4 and not caught_up and shed == {CAMERA: 2, GLOVE: 1}
    assert summary.shed == 3 and summary.max_lag_s > 0.4
    reader = SessionReader(tmp_path / "s.mcap")
    assert reader.topics[CAMERA].message_count == 2 and reader.topics[GLOVE].message_count == 2
    assert reader.topics[topics.COMMAND_ARM].message_count == 3 and reader.topics[topics.OPERATOR].message_count == 3
    counters = reader.metadata[RECORDER_RECORD]
    assert json.loads(counters[CAMERA])["shed"] == 2 and json.loads(counters[CAMERA])["dropped"] == 2
    assert float(counters["max_lag_s"]) > 0.4 and counters["lag_budget_s"] == "0.2"


def test_a_live_session_records_and_shows_that_the_recording_fell_behind(tmp_path):
    """A sim session whose recorder is given a budget its writer cannot keep (1 ms: it polls every 20 ms)."""
    out = tmp_path / "s.mcap"
    rec = LiveSession(RecordOptions(out=out, rig=RIGS / "sim.toml"))
    rec.start()
    try:
        wait_opened(rec)
        rec.recorder.lag_budget_ns = 1_000_000
        wait_until(lambda: "behind" in rec.loop.snapshot.message, 10.0, what="the preview says so")
        shown = rec.loop.snapshot.message
    finally:
        rec.stop()
    assert "camera frames" in shown
    notes = [m.payload.data["event"] for m in SessionReader(out).messages([topics.OPERATOR])]
    assert "recording_behind" in notes, notes
    counters = SessionReader(out).metadata[RECORDER_RECORD]
    assert counters["writer_priority"]
    shed = {t: json.loads(v)["shed"] for t, v in counters.items() if t.startswith("/")}
    assert shed["/camera/cam_front/image"] > 0
    assert not any(n for t, n in shed.items() if t.startswith("/command/") or t.startswith("/events/")), shed


def test_a_queue_the_writer_empties_meanwhile_is_no_error(tmp_path):
    """The writer pops without log()'s lock: between log() reading the queue's length and its oldest entry the
    writer may take the last one. log() must go on (a raise here failed a live session's loop)."""
    from collections import deque

    from teleprev.messages import Event, Logged
    from teleprev.session.recorder import Recorder

    class EmptiedMeanwhile(deque):
        def __len__(self):
            n = super().__len__()
            self.clear()  # the writer's popleft, just after the length was read
            return n

    rec = Recorder(tmp_path / "s.mcap", lag_budget_s=0.2)
    try:
        rec._queue = EmptiedMeanwhile([(0, Logged("/x", 1, Event(1, "teleprev.OperatorEvent", {"event": "a"})))])
        assert rec.log(Logged("/x", 2, Event(2, "teleprev.OperatorEvent", {"event": "b"})))
    finally:
        rec._queue = deque()
        rec.close()
