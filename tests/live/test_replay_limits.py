"""Replay to a robot keeps the motion limits: a session that fails the audit is refused unless played
--smooth, which re-commands it through the pipeline's jerk-limited generator; commands are stamped with
when they run, so playing faster cannot hide accelerations; the engage ramp keeps the limits too."""

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np

from teleprev.live.playback import build_player
from teleprev.pipeline.derivatives import divided_differences

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v1.mcap"  # format 1: speed caps only, fails the audit


def _play_to_sim_arm(smoothed: bool, force_speed: float | None = None):
    """Play episode 0 of the fixture to the rig's robot (the sim arm, which faults like an xArm would)."""
    player, runners, tap, rig, message = build_player(FIXTURE, 0, 1.0, "arm", smoothed=smoothed)
    if force_speed is not None:
        player.speed = force_speed
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
    return player, arm, sent


def test_the_cli_refuses_to_send_a_session_that_fails_the_audit_to_the_robot():
    run = subprocess.run([sys.executable, "-m", "teleprev.cli.app", "replay", str(FIXTURE), "--episode", "0", "--to", "arm",
                          "--no-preview", "--engage-after", "0.1"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1, run.stdout + run.stderr
    said = " ".join(run.stdout.split())  # rich wraps lines
    assert "fails the audit" in said and "--smooth" in said and "accel" in said


def test_played_faster_than_its_accelerations_allow_the_sim_arm_faults():
    player, *_ = build_player(FIXTURE, 0, 1.0, "arm")
    assert player.speed < 0.2  # the recording's accelerations are ~50x the limit: played at most 1/sqrt(50) as fast
    player, arm, _ = _play_to_sim_arm(smoothed=False, force_speed=1.0)
    assert arm.fault  # what a servo-mode xArm does with speed-capped commands at their own pace
    assert "controller fault" in player.state.message  # the player stopped and says why


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
