"""Unattended record: an engage the pipeline refuses (nothing previewed yet, the hand's measured state
inside its clearance margin) is asked again until the episode ends, so the session still gets commands."""

from teleprev.live.record.run import run_script
from teleprev.live.record.session import LiveSession, RecordOptions


def test_a_refused_engage_is_asked_again(tmp_path):
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap"))
    asked = []
    engage = rec.loop.engage

    def refuse_the_first_two(reason="key", unattended=False):  # as the pipeline refuses: the request has no effect
        asked.append(unattended)
        if len(asked) > 2:
            engage(reason, unattended)

    rec.loop.engage = refuse_the_first_two
    rec.start()
    try:
        run_script(rec, duration=3.0, episodes=1, engage_after=0.5)
    finally:
        summary = rec.stop()
    assert len(asked) >= 3
    assert summary.streams["/command/arm"].written > 50


def test_an_engage_while_engaged_changes_nothing(tmp_path):
    """A retried engage that arrives after the first was accepted (a busy machine) is neither counted nor
    recorded (an unattended session engages once per episode), and the commands carry on unbroken."""
    import time

    import numpy as np

    from teleprev import topics
    from teleprev.assembly import motion_limits
    from teleprev.evaluation.audit import audit_session
    from teleprev.pipeline.derivatives import stream_peaks
    from teleprev.session.reader import SessionReader

    path = tmp_path / "s.mcap"
    rec = LiveSession(RecordOptions(out=path))
    rec.start()
    try:
        rec.loop.start_episode("pick_place")
        time.sleep(1.0)
        for _ in range(4):  # the first engages; the others arrive while the arm moves
            rec.loop.engage(unattended=True)
            time.sleep(0.5)
        rec.loop.to_preview("test")
        rec.loop.stop_episode()
    finally:
        rec.stop()
    assert rec.loop.stats.engages == 1
    with SessionReader(path) as reader:
        switches = [m.payload.data["mode"] for m in reader.messages([topics.MODE])]
        assert reader.topics[topics.COMMAND_ARM].message_count > 100
        arm = [m.payload for m in reader.messages([topics.COMMAND_ARM])]
    assert switches == ["execute", "preview"], switches
    # the whole engaged stream as one run (the audit would start a run at each recorded engage)
    peaks = stream_peaks(np.array([c.stamp_ns for c in arm]), np.array([c.positions for c in arm]))
    limits = motion_limits(rec.rig)["arm"]
    assert peaks.runs == 1 and peaks.acceleration.max() <= limits["acceleration"] * (1 + 1e-6), peaks
    assert peaks.jerk.max() <= limits["jerk"] * (1 + 1e-6), peaks
    report = audit_session(path)
    assert report.ok, report.streams
