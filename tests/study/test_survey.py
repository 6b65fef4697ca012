"""The questionnaire: the paper's wording, answers validated (re-asked or refused), stored beside the session
without touching the recording or what was stored before; and one study from real sim recordings."""

import hashlib
import json
import time

import pytest

from teleprev.errors import ConfigError, SessionError
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.messages import Event, Logged
from teleprev.session.writer import McapSessionWriter
from teleprev.study import survey
from teleprev.study.facts import session_facts
from teleprev.study.questionnaire import QUESTIONS, parse_answer
from tests.helpers.cli import teleprev
from tests.helpers.sessions import RIGS
from tests.helpers.study_sessions import scripted


def cli(*args, stdin=None):
    return teleprev(*args, stdin=stdin or "")


def digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def session(tmp_path):
    return scripted(tmp_path / "s.mcap", "w/ preview", "vacuum", [(10, "success", False)], participant="p3")


def test_the_questionnaire_is_table_iv():
    assert [(q.text, q.low, q.high) for q in QUESTIONS] == [
        ("How mentally demanding was the task?", "Very Low", "Very High"),
        ("How physically demanding was the task?", "Very Low", "Very High"),
        ("How frustrated did you feel while using the system?", "Not at all", "Extremely"),
        ("How much overall effort did the task require?", "Very Little", "Very Much"),
        ("How successful do you feel you were in completing the tasks?", "Very Unsuccessful", "Very Successful"),
    ]
    assert [q.higher_is_better for q in QUESTIONS] == [False, False, False, False, True]


@pytest.mark.parametrize("text", ["", "0", "6", "3.0", "3.5", "three", "²", "-1", "1 2"])
def test_only_1_to_5_is_an_answer(text):
    with pytest.raises(ValueError, match="1 to 5"):
        parse_answer(text)


def test_scripted_answers_are_checked_one_by_one():
    assert survey.parse_answers(" 3, 2,4 ,3,5") == dict(zip(survey.KEYS, (3, 2, 4, 3, 5)))
    with pytest.raises(ConfigError, match="expected 5 answers"):
        survey.parse_answers("3,2,4,3")
    with pytest.raises(ConfigError, match=r"answer 3 \(frustration\).*'x'.*Not at all"):
        survey.parse_answers("3,2,x,3,5")


def test_interactive_survey_reasks_until_valid(session):
    recording = digest(session)
    run = cli("survey", session, stdin="7\n3\ntwo\n\n2\n4\n4\n5\n")
    assert run.returncode == 0, run.stderr
    assert run.stdout.count("is not an answer") == 3
    assert "How frustrated did you feel while using the system?" in run.stdout and "5 = Very Successful" in run.stdout
    stored = json.loads((session.parent / "s.survey.json").read_text())
    assert stored["answers"] == dict(zip(survey.KEYS, (3, 2, 4, 4, 5)))
    assert (stored["participant"], stored["condition"], stored["end_effector"]) == ("p3", "w/ preview", "vacuum")
    assert stored["questionnaire"] == "telepreview-table-iv" and stored["answered"]
    assert digest(session) == recording  # the recording is never rewritten
    assert session_facts(session).answers == stored["answers"]


def test_invalid_answers_change_nothing_stored(session):
    run = cli("survey", session, "--answers", "1,2,3,4,9")
    assert run.returncode == 2 and "answer 5 (perceived_success)" in run.stderr and "'9'" in run.stderr
    assert sorted(p.name for p in session.parent.iterdir()) == ["s.mcap"]  # no sidecar, no temporary file
    assert session_facts(session).answers is None  # reported as missing, not zero

    assert cli("survey", session, "--answers", "2,2,2,2,4").returncode == 0
    sidecar = session.parent / "s.survey.json"
    before = sidecar.read_bytes()
    for args in (["--answers", "1,2,3,4,9", "--replace"], ["--answers", "1,1,1,1,1"]):
        run = cli("survey", session, *args)
        assert run.returncode == 2 and sidecar.read_bytes() == before
    assert "already stored" in run.stderr and "--replace" in run.stderr
    # a stored survey is refused before any question is asked
    run = cli("survey", session, stdin="1\n1\n1\n1\n1\n")
    assert run.returncode == 2 and "How mentally" not in run.stdout and sidecar.read_bytes() == before
    # an unfinished interactive survey stores nothing
    run = cli("survey", session, "--replace", stdin="1\n1\n")
    assert run.returncode == 1 and "nothing stored" in run.stdout and sidecar.read_bytes() == before
    assert cli("survey", session, "--answers", "1,1,1,1,1", "--replace").returncode == 0
    assert session_facts(session).answers == dict.fromkeys(survey.KEYS, 1)


def test_a_failed_write_leaves_the_stored_survey_whole(session, monkeypatch):
    t = survey.target(session)
    survey.store(t, dict(zip(survey.KEYS, (2, 2, 2, 2, 4))))
    before = t.sidecar.read_bytes()

    def dump_half(obj, f, **kw):
        f.write('{"answers": {"mental_')
        raise OSError("disk full")

    monkeypatch.setattr(survey.json, "dump", dump_half)
    with pytest.raises(OSError):
        survey.store(t, dict(zip(survey.KEYS, (5, 5, 5, 5, 1))), replace=True)
    assert t.sidecar.read_bytes() == before
    assert sorted(p.name for p in session.parent.iterdir()) == ["s.mcap", "s.survey.json"]


def test_unusable_survey_files_are_named(session, tmp_path):
    sidecar = session.parent / "s.survey.json"
    sidecar.write_text('{"answers": {"mental_demand": 3')
    with pytest.raises(SessionError, match="s.survey.json.*cannot be read"):
        session_facts(session)
    sidecar.write_text(json.dumps({"answers": dict(zip(survey.KEYS, (3, 2, 0, 3, 5)))}))
    with pytest.raises(SessionError, match=r"answers.frustration is 0"):
        session_facts(session)
    # a survey copied next to another recording is not counted for it
    (tmp_path / "o").mkdir()
    other = scripted(
        tmp_path / "o" / "s.mcap", "w/ preview", "vacuum", [(10, "success", False)], answers=(1, 1, 1, 1, 1)
    )
    with McapSessionWriter(tmp_path / "late.mcap", {"session": {"condition": "x"}}) as w:
        w.write(Logged("/events/mode", 5 * 10**12, Event(5 * 10**12, "teleprev.ModeSwitch", {"mode": "preview"})))
    (tmp_path / "late.survey.json").write_bytes((other.parent / "s.survey.json").read_bytes())
    with pytest.raises(SessionError, match="belongs to another recording"):
        session_facts(tmp_path / "late.mcap")


def test_sessions_without_the_study_record_use_the_stem(tmp_path):
    with McapSessionWriter(tmp_path / "old.mcap", {"session": {"condition": "w/o preview"}}) as w:
        w.write(Logged("/events/mode", 10**12, Event(10**12, "teleprev.ModeSwitch", {"mode": "preview"})))
    assert cli("survey", tmp_path / "old.mcap", "--answers", "3,3,3,3,3").returncode == 0
    assert session_facts(tmp_path / "old.mcap").answers == dict.fromkeys(survey.KEYS, 3)
    assert (tmp_path / "old.survey.json").exists()


def test_a_study_of_real_sim_recordings(tmp_path):
    """The whole path: record --practice with the ready key, record episodes marked y/f, survey, study."""
    common = dict(rig=RIGS / "sim.toml", task="pick_place", participant="p9", condition="w/ preview")
    practice = LiveSession(RecordOptions(out=tmp_path / "practice.mcap", practice=True, **common)).start()
    time.sleep(0.6)
    practice.loop.note("ready")
    practice.stop()

    rec = LiveSession(RecordOptions(out=tmp_path / "trial.mcap", **common)).start()
    for success in (True, False):
        rec.loop.start_episode("pick_place")
        time.sleep(0.4)
        rec.loop.stop_episode()
        rec.loop.mark_outcome(success)
    rec.stop()

    trial = session_facts(tmp_path / "trial.mcap")
    assert [e.outcome for e in trial.episodes] == ["success", "failure"]
    assert all(0.35 < e.duration_s < 0.6 for e in trial.episodes)
    p = session_facts(tmp_path / "practice.mcap")
    assert p.practice and 0.55 < p.practice_time_s < 0.9

    assert cli("survey", tmp_path / "trial.mcap", "--answers", "2,1,1,2,5").returncode == 0
    assert (tmp_path / "trial.survey.json").exists()  # the sidecar the recording names
    run = cli("study", tmp_path / "trial.mcap", tmp_path / "practice.mcap", "--out", tmp_path / "out")
    assert run.returncode == 0, run.stderr
    assert f"{trial.episodes[0].duration_s:.1f} ± n/a (n=1)" in run.stdout and "50% of 2" in run.stdout
    assert f"{p.practice_time_s:.1f} ± n/a (n=1)" in run.stdout and "5.00 ± n/a" in run.stdout
    assert (tmp_path / "out" / "likert.png").exists() and (tmp_path / "out" / "practice_time.png").exists()
