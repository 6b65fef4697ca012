"""`teleprev audit`: a session recorded now keeps to the limits; the format-1 fixture (recorded with speed
caps only) does not, and the command exits 1 saying why."""

import json
from pathlib import Path

import pytest

from teleprev.evaluation.audit import audit_session
from tests.helpers.cli import teleprev

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v1.mcap"


@pytest.fixture
def session(sim_session):
    return sim_session


def test_a_new_session_passes_the_audit(session):
    report = audit_session(session)
    arm, hand = report.streams
    assert arm.commands > 200 and hand.commands > 200
    assert report.ok, [s.violations for s in report.streams]
    assert arm.ratios["accel"] <= 1 + 1e-6 and arm.ratios["jerk"] <= 1 + 1e-6 and hand.ratios["accel"] <= 1 + 1e-6
    assert hand.swept_colliding == 0 and report.hand_state_colliding == 0 and report.hand_state_samples > 100


def test_the_cli_fails_the_old_session_and_writes_json(session, tmp_path):
    out = tmp_path / "audit.json"
    run = teleprev("audit", session, FIXTURE, "--json", out)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "audit failed" in run.stdout and "accel" in run.stdout
    data = json.loads(out.read_text())
    assert [d["ok"] for d in data] == [True, False]
    old_arm = data[1]["streams"][0]
    assert old_arm["ratios"]["accel"] > 10  # speed caps alone: hundreds of rad/s^2


def _sweep_session(path: Path, speed_of_joint1: float) -> Path:
    """A session of the current format whose arm commands turn joint 1 of an outstretched xArm6 back and forth
    (a smooth sine, within every joint limit), the flange far from its axis: fast enough, it passes the
    flange's 1.0 m/s cap."""
    import numpy as np

    from teleprev.messages import JointSample, Logged
    from teleprev.session.writer import McapSessionWriter

    names = tuple(f"joint{i}" for i in range(1, 7))
    pose = np.array([0.0, 0.5, -2.0, 0.0, 0.0, 0.0])  # the flange 0.63 m from the axis of joint 1
    w = 4.0  # rad/s: the sine's accel amplitude * w^2 and jerk * w^3 stay within 10 rad/s^2 and 500 rad/s^3
    period = 8_333_333
    with McapSessionWriter(path) as writer:
        for k in range(600):
            t = 1_000_000_000 + k * period
            q = pose.copy()
            q[0] = speed_of_joint1 / w * (1.0 - np.cos(w * k * period / 1e9))  # from rest
            writer.write(Logged("/command/arm", t, JointSample(t, names, q)))
    return path


def test_the_audit_flags_commands_that_pass_the_flange_speed_cap(tmp_path):
    from teleprev.rig import default_rig_path

    fast = audit_session(_sweep_session(tmp_path / "fast.mcap", 2.0), default_rig_path()).streams[0]
    assert fast.ratios["speed"] < 1 and fast.ratios["accel"] < 1 and fast.ratios["jerk"] < 1  # joints: fine
    assert fast.tcp_speed_limit == 1.0 and fast.tcp_speed_max > 1.1
    assert any(v.startswith("tcp_speed ") for v in fast.violations), fast.violations
    slow = audit_session(_sweep_session(tmp_path / "slow.mcap", 0.5), default_rig_path()).streams[0]
    assert 0.1 < slow.tcp_speed_max < 1.0 and slow.violations == []
