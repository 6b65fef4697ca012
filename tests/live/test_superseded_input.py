"""A session loop that falls behind steps the newest glove sample, not its backlog (issue 42): every sample
is still recorded, each one it did not step is named on /events/superseded just before it, and the re-run
skips the same steps, so that the session reproduces bit for bit. Real UDP on loopback into a VMC glove."""

from __future__ import annotations

import threading
import time

from teleprev import topics
from teleprev.evaluation.evaluate import evaluate
from teleprev.evaluation.reproduce import rerun_session
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from tests.helpers.ports import free_port
from tests.helpers.sessions import engage_until_accepted, wait_opened
from tests.helpers.vmc import VmcSender, rig_text
from tests.helpers.wait import wait_until

GLOVE = "/glove/glove/hand"


def test_a_loop_behind_steps_the_newest_glove_sample_records_all_and_reruns_bit_for_bit(tmp_path, monkeypatch):
    port = free_port()
    rig = tmp_path / "vmc.toml"
    rig.write_text(rig_text(port))
    out = tmp_path / "s.mcap"
    sender = VmcSender(port)
    rec = LiveSession(RecordOptions(out=out, rig=rig))
    pipeline = rec.driver.pipeline
    step = pipeline.step
    hiccup = threading.Event()
    hiccups = []

    def step_with_a_hiccup(*args, **kwargs):  # the loop held up 0.3 s once (a busy machine), while executing
        if hiccup.is_set():
            hiccup.clear()
            time.sleep(0.3)
            hiccups.append(rec.loop.inbox.queued[GLOVE])
        return step(*args, **kwargs)

    monkeypatch.setattr(pipeline, "step", step_with_a_hiccup)
    rec.start()
    try:
        wait_opened(rec)
        sender.start(rate_hz=120.0)
        assert rec.wait_connected(10.0) == []
        engage_until_accepted(rec)
        time.sleep(0.5)
        hiccup.set()
        wait_until(lambda: hiccups, 10.0, what="the loop's hiccup")
        time.sleep(0.5)
        received = rec.runners["glove"].stats().topics
    finally:
        sender.stop()
        rec.stop()
    superseded = rec.loop.stats.superseded
    assert superseded >= 20, superseded  # ~36 samples came in during the hiccup: all but the newest skipped

    reader = SessionReader(out)
    gloves = [m.log_time_ns for m in reader.messages([GLOVE])]
    assert len(gloves) >= received[GLOVE] and not rec.loop.stats.dropped  # every sample recorded
    markers = list(reader.messages([topics.SUPERSEDED]))
    assert len(markers) == superseded
    glove_times = set(gloves)
    for m in markers:  # each names the glove sample logged just after it
        assert m.payload.data["topic"] == GLOVE and m.payload.data["log_time_ns"] in glove_times
        assert m.log_time_ns < m.payload.data["log_time_ns"]
    steps = sum(1 for _ in reader.messages([topics.STEP_REPORT]))  # one a step
    assert steps == len(gloves) - superseded

    rerun = rerun_session(out)
    assert len(rerun.t_ns) == steps  # the re-run skipped the same samples
    session = evaluate([out]).report["sessions"][0]
    assert session["bit_identical"]
