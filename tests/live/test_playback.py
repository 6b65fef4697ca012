"""teleprev replay: same command sequence at any speed, never faster than the limits, starts in preview."""

import threading
import time

import numpy as np
import pytest

from teleprev.live.replay.playback import build_player
from teleprev.live.replay.player import load_playback, safe_speed
from tests.helpers.sessions import record_sim


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "gripper.mcap"
    record_sim(path, "sim_gripper.toml", seconds=2.5, episodes=1, engage_after=0.8)
    return path


def _play(session, speed, engage_delay=0.0):
    player, runners, tap, rig, message, _ = build_player(session, 0, speed, "sim")
    sent_to_arm = []
    arm = player.actuators["arm"]
    original = arm.send
    arm.send = lambda cmd: (sent_to_arm.append((player.state.mode, cmd.positions.copy())), original(cmd))[1]
    for r in runners:
        r.start()
    thread = threading.Thread(target=player.run)
    thread.start()
    time.sleep(engage_delay)
    before = len(sent_to_arm)
    player.engage()
    thread.join(30)
    for r in runners:
        r.stop()
    return player, sent_to_arm, before


def test_replay_starts_in_preview_and_sends_nothing_until_engaged(session):
    player, sent, before = _play(session, 4.0, engage_delay=0.6)
    assert before == 0
    assert sent and sent[0][0] == "ramp"  # then it moves from where the sim arm is, and plays
    assert any(phase == "playing" for phase, _ in sent)


def test_speed_4_sends_the_same_sequence_as_speed_1(session):
    _, slow, _ = _play(session, 1.0)
    fast_player, fast, _ = _play(session, 4.0)
    played_slow = [q for phase, q in slow if phase == "playing"]
    played_fast = [q for phase, q in fast if phase == "playing"]
    assert len(played_slow) == len(played_fast) > 100
    assert all(np.array_equal(a, b) for a, b in zip(played_slow, played_fast))
    # and they are the recorded commands, unchanged
    p = load_playback(session, 0)
    assert all(np.array_equal(a, b) for a, b in zip(played_fast, p.arm))


def test_speed_is_capped_where_faster_would_exceed_a_joint_limit(session):
    player, *_ = build_player(session, 0, 1000.0, "preview")
    p = player.p
    assert player.speed < 1000.0
    dt = np.diff(p.t_ns) / 1e9 / player.speed
    assert np.all(np.abs(np.diff(p.arm, axis=0)) <= player.arm_guard.speed * dt[:, None] + 1e-9)
    assert safe_speed(p, player.arm_guard.speed, player.effector_guard.speed, 0.5) == 0.5
