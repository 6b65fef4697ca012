"""Replay to a robot keeps the motion limits: a session that fails the audit is refused unless played
--smooth, which re-commands it through the pipeline's jerk-limited generator; commands are stamped with
when they run, so playing faster cannot hide accelerations; the engage ramp keeps the limits too."""

import threading
from pathlib import Path

import numpy as np
import pytest

from teleprev.errors import ConfigError
from teleprev.live.replay import playback
from teleprev.live.replay.playback import build_player
from teleprev.pipeline.derivatives import divided_differences
from tests.helpers.cli import teleprev

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v1.mcap"  # format 1: speed caps only, fails the audit
SIM_RIG = Path(__file__).parents[2] / "rigs" / "sim.toml"  # its robot is the sim arm and hand


def _play(player, runners) -> list:
    """Engage at once and play to the end; the (stamp, positions) the arm was sent."""
    arm = player.actuators["arm"]
    sent, original = [], arm.send
    arm.send = lambda cmd: (sent.append((cmd.stamp_ns, cmd.positions.copy())), original(cmd))[1]
    for r in runners:
        r.start()
    player.engage()
    thread = threading.Thread(target=player.run)
    thread.start()
    thread.join(60)
    for r in runners:
        r.stop()
    return sent


def _play_to_sim_arm(smoothed: bool):
    """Play episode 0 of the fixture to the rig's robot (the sim arm, which faults like an xArm would)."""
    player, runners, tap, rig, message, _ = build_player(FIXTURE, 0, 1.0, "arm", SIM_RIG, smoothed=smoothed)
    return player, player.actuators["arm"], _play(player, runners)


def test_the_cli_refuses_to_send_a_session_that_fails_the_audit_to_the_robot():
    run = teleprev(
        "replay", FIXTURE, "--episode", "0", "--to", "arm", "--rig", SIM_RIG, "--no-preview", "--engage-after", "0.1"
    )
    assert run.returncode == 1, run.stdout + run.stderr
    said = " ".join(run.stdout.split())  # rich wraps lines
    assert "fails the audit" in said and "--smooth" in said and "accel" in said


def test_unsmoothed_it_could_only_be_played_slower_than_recorded_so_it_is_refused():
    with pytest.raises(ConfigError, match="--smooth"):
        build_player(FIXTURE, 0, 1.0, "arm", SIM_RIG)  # ~50x the acceleration limit: 1/sqrt(50) x at most


def test_played_anyway_the_sim_arm_faults_and_the_player_stops_saying_why(monkeypatch):
    monkeypatch.setattr(playback, "safe_speed", lambda *args, **kw: 1.0)  # what replay did before the limits
    player, arm, _ = _play_to_sim_arm(smoothed=False)
    assert arm.fault  # what a servo-mode xArm does with speed-capped commands at their own pace
    assert "controller fault" in player.state.message


def test_smoothed_the_sim_arm_follows_within_the_limits():
    player, arm, sent = _play_to_sim_arm(smoothed=True)
    assert arm.fault == ""
    played = [(t, q) for t, q in sent]
    assert len(played) > 200
    t = np.array([t for t, _ in played], dtype=np.int64)
    q = np.array([q for _, q in played])
    assert np.all(np.diff(t) > 0)
    _, acc, jerk = divided_differences(t, q)
    limits = player.motion.arm
    assert np.abs(acc).max() <= limits.acceleration.max() * 1.05
    assert np.abs(jerk).max() <= limits.jerk.max() * 1.05
    # it ends on the last recorded command, arriving at rest (the last step slower than one step's braking)
    assert np.allclose(q[-1], player.p.arm[-1], atol=1e-6)
    assert np.abs(q[-1] - q[-2]).max() <= limits.acceleration.max() * ((t[-1] - t[-2]) / 1e9) ** 2
    assert player.state.message == ""


def test_smoothed_at_half_speed_is_generated_for_the_played_time():
    player, runners, tap, rig, message, _ = build_player(FIXTURE, 1, 0.5, "arm", SIM_RIG, smoothed=True)
    assert player.speed == 0.5
    p = player.p
    played_ns = np.diff(p.t_ns) / 0.5  # what the Player waits between commands at this speed
    assert played_ns.max() <= 1e9 / 120 + 1  # no pause a servo arm would stand through
    # in played time (integer ns differences first); stamps are whole ns, which divided differences on
    # 4 ms steps amplify to ~1e-5 of the limit
    _, acc, jerk = divided_differences((p.t_ns - p.t_ns[0]) * 2, p.arm)
    assert np.abs(acc).max() <= player.motion.arm.acceleration.max() * (1 + 1e-4)
    assert np.abs(jerk).max() <= player.motion.arm.jerk.max() * (1 + 1e-3)


def test_a_fresh_recording_replays_to_the_sim_robot_without_a_fault(sim_session):
    player, runners, tap, rig, message, _ = build_player(sim_session, 0, 2.0, "sim")
    assert player.speed == 1.0  # recorded at the limits: 2x would break them
    hand_steps = int(player.p.sent("effector").sum())
    _play(player, runners)
    assert player.actuators["arm"].fault == "" and player.state.message == ""
    played_hand = sum(1 for phase, kind, _ in player.state.sent if phase == "playing" and kind == "hand")
    assert played_hand == hand_steps  # each side at its own recorded stamps, nothing held in between
