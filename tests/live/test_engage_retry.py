"""Unattended record: an engage the pipeline refuses (nothing previewed yet, the hand's measured state
inside its clearance margin) is asked again until the episode ends, so the session still gets commands."""

from teleprev.live.run import run_script
from teleprev.live.session import LiveSession, RecordOptions


def test_a_refused_engage_is_asked_again(tmp_path):
    rec = LiveSession(RecordOptions(out=tmp_path / "s.mcap"))
    asked = []
    control = rec.loop.control

    def refuse_the_first_two(action, **kwargs):  # as the pipeline refuses: the request has no effect
        if action == "mode" and kwargs.get("mode") == "execute":
            asked.append(kwargs)
            if len(asked) <= 2:
                return None
        return control(action, **kwargs)

    rec.loop.control = refuse_the_first_two
    rec.start()
    try:
        run_script(rec, duration=3.0, episodes=1, engage_after=0.5)
    finally:
        summary = rec.stop()
    assert len(asked) >= 3
    assert summary.streams["/command/arm"].written > 50
