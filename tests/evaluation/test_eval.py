"""teleprev eval: bit-identical re-runs, metrics, the regression gate, plots."""

import json

import numpy as np
import pytest

from teleprev.evaluation.evaluate import evaluate
from teleprev.evaluation.report import Tolerance, Tolerances, compare
from tests.helpers.cli import teleprev
from tests.helpers.sessions import record_sim


@pytest.fixture(scope="module")
def gripper_session(tmp_path_factory):
    path = tmp_path_factory.mktemp("eval") / "gripper.mcap"
    record_sim(path, "sim_gripper.toml", seconds=3.0, episodes=2, engage_after=1.0)
    return path


def test_rerun_reproduces_the_recorded_commands_bit_for_bit(gripper_session):
    result = evaluate([gripper_session])
    session = result.report["sessions"][0]
    assert session["bit_identical"] is True
    o = result.report["overall"]
    assert o["steps"] > 500 and len(session["episodes"]) == 2
    r = result.reruns[0]
    arm = r.commands["/command/arm"]  # sampled by the paced sender at its ticks
    commanded = ~np.isnan(arm.rerun).any(axis=1)
    assert commanded.sum() > 200  # there was something to reproduce
    assert np.array_equal(arm.rerun, arm.recorded)
    assert o["arm_speed_max"] <= 2.14 + 1e-9  # the rig's arm speed cap


def test_a_perturbed_calibration_does_not_reproduce_and_says_what_moved(gripper_session, tmp_path):
    from teleprev.session.reader import SessionReader

    meta = SessionReader(gripper_session).metadata
    cal = tmp_path / "perturbed.toml"
    cal.write_text("[calibration]\nsuit_yaw = 0.35\n")
    rig = tmp_path / "rig.toml"
    rig.write_text(meta["rig"]["toml"].replace("[rig]", f'[rig]\ncalibration = "{cal}"', 1))
    baseline = evaluate([gripper_session]).report
    perturbed = evaluate(
        [gripper_session],
        rig=rig,
        baseline=baseline,
        tolerances=Tolerances({"reproduced": Tolerance(), "arm_speed_max": Tolerance(rel=0.0, worse="either")}),
    )
    assert perturbed.report["sessions"][0]["bit_identical"] is False
    moved = {r.metric for r in perturbed.regressions}
    assert "reproduced" in moved


def test_regression_gate_passes_its_own_baseline_and_fails_past_a_tolerance(gripper_session, tmp_path):
    report = tmp_path / "baseline.json"
    assert teleprev("eval", gripper_session, "--out", report).returncode == 0
    same = teleprev("eval", gripper_session, "--baseline", report)
    assert same.returncode == 0 and "no regression" in same.stdout
    assert "evaluating 1 session(s)" in same.stdout and "1/1 gripper.mcap: done" in same.stdout  # progress, piped
    # a baseline whose hand moved much less: today's hand speed is a regression past 10 %
    data = json.loads(report.read_text())
    data["overall"]["hand_speed_max"] *= 0.5
    report.write_text(json.dumps(data))
    worse = teleprev("eval", gripper_session, "--baseline", report)
    assert worse.returncode == 1
    assert "hand_speed_max" in worse.stdout and "regression" in worse.stdout


def test_compare_names_each_metric_and_how_far_it_moved():
    base = {"overall": {"a": 1.0, "b": 0.10, "c": 5.0, "ok": True}}
    now = {"overall": {"a": 1.05, "b": 0.30, "c": 2.0, "ok": False}}
    tol = Tolerances(
        {"a": Tolerance(rel=0.1), "b": Tolerance(abs=0.1), "c": Tolerance(abs=1, worse="lower"), "ok": Tolerance()}
    )
    got = {r.metric: r for r in compare(base, now, tol)}
    assert set(got) == {"b", "c", "ok"}
    assert "+0.2" in got["b"].describe()


def test_plots_are_written_per_episode(gripper_session, tmp_path):
    from teleprev.evaluation.plots import changed_spans, effector_unit, plot_episodes

    result = evaluate([gripper_session])
    paths = plot_episodes(result.reruns[0], tmp_path)
    assert len(paths) == 2 and all(
        p.stat().st_size > 5000 and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths
    )
    # the Corrector's changes are drawn as one span per run of changed steps (a line per step took a minute)
    t = np.arange(8) * 0.01
    changed = np.array([0, 1, 1, 0, 0, 1, 0, 1], dtype=bool)
    assert changed_spans(t, changed) == [(0.01, 0.03), (0.05, 0.06), (0.07, 0.07)]
    assert effector_unit("parallel_gripper") == "m (jaw opening)" and effector_unit("leap_hand") == "rad"
