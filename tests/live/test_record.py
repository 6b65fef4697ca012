"""`teleprev record` end to end on the default (LEAP) sim rig: what reaches the robot, and the screen."""

import io

import numpy as np
import pytest
from rich.console import Console

from teleprev import topics
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.model import load_robot
from teleprev.session.reader import SessionReader
from tests.helpers.cli import teleprev
from tests.helpers.sessions import engage_until_accepted, record_sim, record_what_is_sent
from tests.helpers.wait import wait_until


def test_a_whole_session_in_preview_sends_no_motion_command(tmp_path):
    import time

    from teleprev.live.record.session import LiveSession, RecordOptions

    rec = LiveSession(RecordOptions(out=tmp_path / "p.mcap"))
    doubles = record_what_is_sent(rec)
    rec.start()
    rec.loop.start_episode("pick_place")
    time.sleep(3.0)
    rec.stop()
    assert all(d.sent == [] for d in doubles.values())
    reader = SessionReader(tmp_path / "p.mcap")
    assert topics.COMMAND_ARM not in reader.topics and topics.COMMAND_HAND not in reader.topics
    assert reader.topics[topics.CORRECTED].message_count > 300  # the pipeline ran all along


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "leap.mcap"
    record_sim(path, "sim.toml", seconds=6.0, episodes=1, engage_after=1.0, task="pick_place")
    return path


def test_executed_commands_stay_within_speed_limits_and_never_collide(executed):
    reader = SessionReader(executed)
    hand = load_robot("leap_hand_right")
    robot = load_robot("xarm6_leap_hand")
    for topic, model, cap in ((topics.COMMAND_ARM, robot, 2.14), (topics.COMMAND_HAND, hand, 6.0)):
        msgs = [m.payload for m in reader.messages([topic])]
        assert len(msgs) > 200, topic
        q = np.array([m.positions for m in msgs])
        t = np.array([m.stamp_ns for m in msgs])
        idx = model.indices(msgs[0].names)
        assert np.all(q >= model.lower[idx] - 1e-12) and np.all(q <= model.upper[idx] + 1e-12)
        speed = np.abs(np.diff(q, axis=0)) / (np.diff(t) / 1e9)[:, None]
        assert speed.max() <= cap + 1e-9, (topic, speed.max())
    hand_q = np.array([m.payload.positions for m in reader.messages([topics.COMMAND_HAND])])
    assert not SelfCollisionChecker(hand).pair_matrix(hand_q).any()  # exact check of every hand command


def test_executed_commands_keep_to_the_acceleration_and_jerk_limits_and_the_arm_never_faults(executed):
    from teleprev.pipeline.derivatives import stream_peaks

    reader = SessionReader(executed)
    # (the hand may stop short of a contact by up to 5% over its cap: safety before smoothness)
    for topic, accel, jerk in ((topics.COMMAND_ARM, 10.0, 500.0), (topics.COMMAND_HAND, 200.0 * 1.05, None)):
        msgs = [m.payload for m in reader.messages([topic])]
        # the audit's measure: a run after a sender pause starts from rest where the stream stood
        peaks = stream_peaks(np.array([m.stamp_ns for m in msgs]), np.array([m.positions for m in msgs]))
        assert peaks.acceleration.max() <= accel * (1 + 1e-6), (topic, peaks)
        if jerk is not None:
            assert peaks.jerk.max() <= jerk * (1 + 1e-6), (topic, peaks)
    # the sim arm faults (an error event) on any command over its limits by more than 10%
    events = [m.payload.data for m in reader.messages([topics.DEVICE_EVENT])]
    assert not [e for e in events if e["event"] == "error"], events
    assert "arm" in {e["device"] for e in events}  # the events are there to be read


def test_unattended_record_cli_writes_every_stream(tmp_path):
    out = tmp_path / "cli.mcap"
    run = teleprev(
        "record", "--out", out, "--duration", "4", "--episodes", "2", "--engage-after", "1", "--task", "pour"
    )
    assert run.returncode == 0, run.stderr
    reader = SessionReader(out)
    have = set(reader.topics)
    for needed in (
        "/glove/glove/hand",
        "/suit/suit/wrist",
        "/camera/cam_front/image",
        "/arm/arm/state",
        "/hand/hand/state",
        topics.RETARGETED,
        topics.CORRECTED,
        topics.ARM_TARGET,
        topics.COMMAND_ARM,
        topics.COMMAND_HAND,
        topics.MODE,
        topics.EPISODE,
        topics.TF,
        topics.STEP_REPORT,
    ):
        assert needed in have, needed
    episodes = reader.episodes()
    assert [e.task for e in episodes] == ["pour", "pour"]
    modes = [m.payload.data["mode"] for m in reader.messages([topics.MODE])]
    assert modes == ["execute", "preview", "execute", "preview"]


def test_the_terminal_preview_shows_the_mode_and_the_robot(executed):
    import time

    from teleprev.live.record.run import make_dashboard
    from teleprev.live.record.session import LiveSession, RecordOptions

    rec = LiveSession(RecordOptions(out=executed.parent / "screen.mcap"))
    rec.start()
    try:
        rec.loop.start_episode("hang")
        time.sleep(1.2)
        console = Console(file=io.StringIO(), width=140, height=44, record=True)
        dash = make_dashboard(rec, "side")
        console.print(dash.render(rec.loop.snapshot, rec.device_rows(), 140, 44, rec.clock.now_ns()))
        preview_text = console.export_text()
        engage_until_accepted(rec)
        wait_until(lambda: rec.loop.snapshot.mode == "execute", what="EXECUTE in the snapshot")
        console = Console(file=io.StringIO(), width=140, height=44, record=True)
        console.print(dash.render(rec.loop.snapshot, rec.device_rows(), 140, 44, rec.clock.now_ns()))
        execute_text = console.export_text()
        small = Console(file=io.StringIO(), width=50, height=14, record=True)
        small.print(dash.render(rec.loop.snapshot, rec.device_rows(), 50, 14, rec.clock.now_ns()))
        small_text = small.export_text()
    finally:
        rec.stop()
    assert "PREVIEW" in preview_text and "EXECUTE" in execute_text
    braille = sum(0x2801 <= ord(c) <= 0x28FF for c in preview_text)
    assert braille > 200  # the robot is drawn
    assert "episode 0" in preview_text and "[hang]" in preview_text and "glove" in preview_text
    assert "EXECUTE" in small_text and sum(0x2801 <= ord(c) <= 0x28FF for c in small_text) == 0  # status only
