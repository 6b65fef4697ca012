"""A bug in the pipeline (an exception in the session loop) while engaged: the robot brakes to rest within
its limits, execute is refused from then on, the devices keep being recorded, and the session says why."""

from teleprev import topics
from teleprev.evaluation.audit import audit_session
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from tests.helpers.sessions import engage_until_accepted
from tests.helpers.wait import wait_until


def test_an_exception_in_the_loop_brakes_the_robot_and_keeps_recording(tmp_path):
    path = tmp_path / "s.mcap"
    rec = LiveSession(RecordOptions(out=path))
    rec.start()
    try:
        rec.loop.start_episode("pick_place")
        engage_until_accepted(rec, unattended=True)
        wait_until(lambda: rec.loop.stats.commands_sent["arm"] > 60, 10.0, what="commands while engaged")
        assert rec.loop.stats.engages == 1

        def broken(msg, *args):
            raise FloatingPointError("a bug in the step")

        rec.loop.driver.feed = broken
        wait_until(lambda: rec.failure, 5.0, what="the loop's failure")
        failed_ns = rec.clock.now_ns()
        glove = rec.loop.stats.streams["/glove/glove/hand"]
        seen = glove.count
        rec.loop.engage()  # the operator tries again: refused
        wait_until(lambda: rec.loop.snapshot.message.startswith("cannot switch to execute"), 5.0,
                   what="the operator's engage refused")
        wait_until(lambda: not rec.loop.relay.active, 5.0, what="the commands braked to rest")
        wait_until(lambda: glove.count > seen + 40, 10.0, what="the glove recorded after the failure")
        rec.loop.stop_episode()
    finally:
        rec.stop()
    assert rec.failure == "the session loop failed: FloatingPointError: a bug in the step"
    assert rec.loop.stats.engages == 1
    with SessionReader(path) as reader:
        modes = [m.payload.data for m in reader.messages([topics.MODE])]
        operator = [m.payload.data for m in reader.messages([topics.OPERATOR])]
        after = [m.log_time_ns for m in reader.messages(["/glove/glove/hand"]) if m.log_time_ns > failed_ns]
        commands = [m.log_time_ns for m in reader.messages([topics.COMMAND_ARM])]
        assert reader.metadata["loop"]["failure"] == rec.failure
    assert modes[-1] == {"mode": "preview", "reason": "halt"}, modes
    assert [o["event"] for o in operator] == ["loop_failed"] and "FloatingPointError" in operator[0]["detail"]
    assert len(after) > 30  # the glove was still recorded after the failure
    assert commands and commands[-1] < failed_ns + 2_000_000_000  # braked to rest, then nothing more
    report = audit_session(path)
    assert report.ok, [s.violations for s in report.streams]
