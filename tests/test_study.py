"""User-study support on scripted sessions with known durations, outcomes, practice times and answers."""

import json
import subprocess
import sys

import numpy as np
import pytest

from teleprev.errors import ConfigError, SessionError
from teleprev.messages import Event, Logged
from teleprev.session import topics
from teleprev.session.writer import McapSessionWriter
from teleprev.study import survey
from teleprev.study.stats import group, preview_column, session_facts, table_iii

S = 10**9


def scripted(path, condition, end_effector, episodes=(), practice_s=None, participant="p1"):
    """episodes: (duration_s, outcome or None, discarded); practice_s: ready this long after the start."""
    meta = {"session": {"participant": participant, "condition": condition, "end_effector": end_effector, "task": "pick_place",
                        "practice": "true" if practice_s is not None else "false"},
            "study": {"survey_sidecar": path.with_suffix(".survey.json").name}}
    t = 1000 * S
    with McapSessionWriter(path, meta) as w:
        def event(topic, schema, data):
            nonlocal t
            t += 1
            w.write(Logged(topic, t, Event(t, schema, data)))
        if practice_s is not None:
            event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": "practice_start"})
            t += int(practice_s * S) - 1
            event(topics.OPERATOR, "teleprev.OperatorEvent", {"event": "ready"})
        for k, (duration, outcome, discarded) in enumerate(episodes):
            event(topics.EPISODE, "teleprev.EpisodeEvent", {"event": "start", "episode": k, "task": "pick_place"})
            t += int(duration * S) - 1
            event(topics.EPISODE, "teleprev.EpisodeEvent", {"event": "stop", "episode": k, "task": "pick_place"})
            if discarded:
                event(topics.EPISODE, "teleprev.EpisodeEvent", {"event": "discard", "episode": k, "task": "pick_place"})
            if outcome:
                event(topics.EPISODE, "teleprev.EpisodeEvent", {"event": "outcome", "episode": k, "task": "pick_place", "outcome": outcome})
            t += 2 * S
    return path


@pytest.fixture
def study_sessions(tmp_path):
    s = {
        "leap_without": scripted(tmp_path / "a.mcap", "w/o preview", "leap_hand", [(20, "success", False), (26, "success", False), (40, "failure", False)]),
        "leap_with": scripted(tmp_path / "b.mcap", "w/ preview", "leap_hand", [(12, "success", False), (16, "success", False), (99, "success", True)]),
        "leap_with_2": scripted(tmp_path / "c.mcap", "w/ preview", "leap_hand", [(14, "success", False), (18, None, False)], participant="p2"),
        "practice_with": scripted(tmp_path / "d.mcap", "w/ preview", "leap_hand", practice_s=95.0),
        "practice_with_2": scripted(tmp_path / "e.mcap", "w/ preview", "leap_hand", practice_s=125.0, participant="p2"),
        "gripper_without": scripted(tmp_path / "f.mcap", "without preview", "parallel_gripper", [(17, "success", False)]),
        "gripper_with": scripted(tmp_path / "g.mcap", "With Preview", "parallel_gripper", [(14, "success", False)]),
    }
    survey.store(s["leap_without"], dict(zip(survey.KEYS, (4, 4, 3, 4, 2))))
    survey.store(s["leap_with"], dict(zip(survey.KEYS, (2, 3, 1, 2, 5))))
    survey.store(s["leap_with_2"], dict(zip(survey.KEYS, (3, 2, 2, 3, 4))))
    return s


def test_tables_have_the_expected_values(study_sessions):
    facts = [session_facts(p) for p in study_sessions.values()]
    groups = {(g.condition, g.end_effector): g for g in group(facts)}
    without = groups[("w/o preview", "leap_hand")]
    assert without.execution_time_s.mean == pytest.approx(23.0) and without.execution_time_s.std == pytest.approx(np.std([20, 26], ddof=1))
    assert without.success_rate == pytest.approx(2 / 3)
    with_ = groups[("w/ preview", "leap_hand")]
    # successful kept episodes 12, 16, 14; the discarded 99 s and the unmarked 18 s are left out
    assert with_.execution_time_s.mean == pytest.approx(14.0) and with_.execution_time_s.n == 3
    assert with_.success_rate == 1.0 and with_.episodes_with_outcome == 3
    assert with_.practice_time_s.mean == pytest.approx(110.0) and with_.practice_time_s.std == pytest.approx(np.std([95, 125], ddof=1))
    assert with_.likert["perceived_success"].mean == pytest.approx(4.5) and with_.likert["mental_demand"].mean == pytest.approx(2.5)
    assert with_.surveys == 2
    assert without.practice_time_s.mean is None  # no practice recorded: missing, not zero
    rows = {r.end_effector: r for r in table_iii(list(groups.values()))}
    assert rows["leap_hand"].improvement_s == pytest.approx(14.0 - 23.0)
    assert rows["parallel_gripper"].improvement_s == pytest.approx(-3.0)
    gripper = groups[("without preview", "parallel_gripper")]
    assert gripper.surveys == 0 and gripper.likert["frustration"].mean is None


def test_study_cli_writes_csv_and_plots(study_sessions, tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "teleprev.cli.app", "study", *map(str, study_sessions.values()), "--out", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "Table III" in run.stdout and "-9.0" in run.stdout and "no survey for" in run.stdout
    rows = (out / "table_iii.csv").read_text().splitlines()
    assert rows[0].startswith("end_effector") and any(r.startswith("leap_hand,23.0") for r in rows)
    for png in ("likert.png", "practice_time.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_invalid_answers_are_refused_and_nothing_stored_changes(study_sessions):
    path = study_sessions["leap_with"]
    sidecar = survey.sidecar_path(path)
    before = sidecar.read_bytes()
    for bad in ("3,2,4,3", "3,2,4,3,6", "3,two,4,3,5", "0,1,1,1,1"):
        with pytest.raises(ConfigError):
            survey.parse_answers(bad)
    with pytest.raises(SessionError, match="already stored"):
        survey.store(path, dict(zip(survey.KEYS, (1, 1, 1, 1, 1))))
    assert sidecar.read_bytes() == before
    run = subprocess.run([sys.executable, "-m", "teleprev.cli.app", "survey", str(path), "--answers", "1,2,3,4,9", "--replace"],
                         capture_output=True, text=True)
    assert run.returncode == 2 and "perceived_success" in run.stderr and "1 to 5" in run.stderr
    assert sidecar.read_bytes() == before


def test_interactive_survey_reasks_until_valid(study_sessions):
    replies = iter(["", "7", "3", "two", "2", "4", "4", "5"])
    said = []
    answers = survey.ask(lambda prompt: next(replies), said.append)
    assert answers == dict(zip(survey.KEYS, (3, 2, 4, 4, 5)))
    assert len(said) == 3 and all("1 to 5" in s for s in said)


def test_a_session_without_survey_is_reported_as_missing(study_sessions):
    facts = session_facts(study_sessions["gripper_with"])
    assert facts.answers is None


def test_the_questionnaire_has_the_papers_wording():
    texts = [q.text for q in survey.QUESTIONS]
    assert texts[0] == "How mentally demanding was the task?"
    assert texts[4] == "How successful do you feel you were in completing the tasks?"
    assert [q.higher_is_better for q in survey.QUESTIONS] == [False, False, False, False, True]


@pytest.mark.parametrize("text, column", [("w/ preview", "with"), ("With Preview", "with"), ("w/o preview", "without"),
                                          ("no preview", "without"), ("baseline", None)])
def test_conditions_map_to_table_iii_columns(text, column):
    assert preview_column(text) == column
