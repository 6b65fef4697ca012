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
