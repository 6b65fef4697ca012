"""User-study tables from scripted sessions with known episode durations, outcomes, practice times and answers.

The sessions are real MCAP files written with McapSessionWriter and read back through SessionReader;
they hold only metadata and events, so every expected value below follows from the script by hand.
"""

import csv

import pytest

from teleprev.errors import ConfigError
from teleprev.study import survey
from teleprev.study.facts import session_facts
from teleprev.study.stats import ColumnMap, Summary, group, preview_column, table_iii
from tests.helpers.cli import teleprev
from tests.helpers.study_sessions import scripted


def study_sessions(d):
    ok, fail = "success", "failure"
    return [
        scripted(
            d / "a.mcap",
            "w/o preview",
            "leap_hand",
            [(20, ok, False), (26, ok, False), (40, fail, False)],
            answers=(4, 4, 3, 4, 2),
        ),
        scripted(d / "b.mcap", "w/o preview", "leap_hand", [(23, ok, False), (30, None, False)], participant="p2"),
        scripted(
            d / "c.mcap",
            "w/ preview",
            "leap_hand",
            [(12, ok, False), (16, ok, False), (99, ok, True)],
            answers=(2, 3, 1, 2, 5),
        ),
        scripted(
            d / "d.mcap",
            "W/ Preview",
            "leap_hand",
            [(14, ok, False), (18, None, False), (60, ok, False, False)],
            participant="p2",
            answers=(3, 2, 2, 3, 4),
        ),
        scripted(d / "e.mcap", "w/ preview", "leap_hand", practice_s=95.0),
        scripted(d / "f.mcap", "w/ preview", "leap_hand", practice_s=125.0, participant="p2", task="warm-up"),
        scripted(d / "g.mcap", "w/o preview", "leap_hand", practice_s=-1),  # never pressed ready
        scripted(d / "h.mcap", "without preview", "parallel_gripper", [(17, ok, False)]),
        scripted(
            d / "i.mcap", "with preview", "parallel_gripper", [(14, ok, False), (15, ok, False), (9, fail, False)]
        ),
        scripted(d / "j.mcap", "baseline", "leap_hand", [(30, ok, False), (40, ok, False)], practice_s=None),
        scripted(d / "k.mcap", "baseline", "leap_hand", practice_s=200.0, practice_start=False),
        scripted(d / "l.mcap", "w/ preview", "leap_hand", [(50, ok, False)], task="pour"),
    ]


@pytest.fixture(scope="module")
def paths(tmp_path_factory):
    return study_sessions(tmp_path_factory.mktemp("study"))


@pytest.fixture(scope="module")
def facts(paths):
    return [session_facts(p) for p in paths]


def test_session_facts_read_back(facts):
    by = {f.path.name: f for f in facts}
    d = by["d.mcap"]
    assert [e.duration_s for e in d.episodes] == [14.0, 18.0, None]  # the outcome comes after the stop
    assert [e.outcome for e in d.episodes] == ["success", None, "success"]
    assert by["e.mcap"].practice_time_s == pytest.approx(95.0)
    assert by["k.mcap"].practice_time_s == pytest.approx(
        203.0
    )  # no practice_start event: from the session's first message
    assert by["g.mcap"].practice and by["g.mcap"].practice_time_s is None
    assert by["a.mcap"].answers == dict(zip(survey.KEYS, (4, 4, 3, 4, 2)))
    assert by["b.mcap"].answers is None and by["l.mcap"].task == "pour"


def test_groups_have_the_expected_values(facts):
    groups = {(g.condition, g.end_effector): g for g in group(facts)}
    without = groups[("w/o preview", "leap_hand")]
    assert list(without.tasks) == ["pick_place"]
    pick = without.tasks["pick_place"]
    # successful kept episodes 20, 26, 23: mean 23, sample std 3; the 40 s failure and the unmarked 30 s are out
    assert pick.execution_time_s == Summary(pytest.approx(23.0), pytest.approx(3.0), 3)
    assert pick.success_rate == pytest.approx(3 / 4) and pick.judged == 4 and pick.unmarked == 1
    assert without.sessions == 3 and without.participants == 2
    assert without.practice_sessions == 1 and without.practice_time_s == Summary(None, None, 0)  # no ready key: missing
    assert without.surveys == 1 and without.not_surveyed == 1

    with_ = groups[("w/ preview", "leap_hand")]
    assert list(with_.tasks) == ["pick_place", "pour"]  # execution time per task; the pour session is in the group
    assert with_.tasks["pick_place"].execution_time_s == Summary(
        pytest.approx(14.0), pytest.approx(8**0.5), 2
    )  # 12, 16 (99 discarded)
    assert with_.tasks["pour"].execution_time_s == Summary(50.0, None, 1)
    # practice is per condition, whatever task it was recorded under: 95 and 125 s
    assert with_.practice_time_s == Summary(pytest.approx(110.0), pytest.approx(21.2132, abs=1e-4), 2)
    assert with_.surveys == 1 and with_.not_surveyed == 1 and with_.likert["perceived_success"] == Summary(5.0, None, 1)
    assert with_.sessions == 4 and with_.participants == 2

    # "W/ Preview" is its own condition in the per-group table (the texts differ) ...
    capital = groups[("W/ Preview", "leap_hand")].tasks["pick_place"]
    assert capital.execution_time_s == Summary(14.0, None, 1)  # 18 s unmarked, 60 s never stopped
    assert capital.success_rate == 1.0 and capital.unmarked == 1

    gripper = groups[("with preview", "parallel_gripper")]
    assert gripper.tasks["pick_place"].success_rate == pytest.approx(2 / 3)
    assert gripper.surveys == 0 and gripper.likert["frustration"] == Summary(None, None, 0)  # no survey: missing, not 0
    assert gripper.practice_sessions == 0 and gripper.practice_time_s.mean is None

    baseline = groups[("baseline", "leap_hand")]
    assert baseline.tasks["pick_place"].execution_time_s.mean == pytest.approx(35.0)
    assert baseline.practice_time_s == Summary(200.0 + 3.0, None, 1)

    only_pour = {(g.condition, g.end_effector): g for g in group(facts, task="pour")}
    assert (
        list(only_pour[("w/ preview", "leap_hand")].tasks) == ["pour"]
        and only_pour[("baseline", "leap_hand")].tasks == {}
    )
    assert (
        only_pour[("w/ preview", "leap_hand")].practice_time_s.n == 2
    )  # --task narrows episodes, not practice or ratings


def test_table_iii_pools_matching_conditions_per_task(facts):
    rows = {(r.task, r.end_effector): r for r in table_iii(facts)}
    leap = rows[("pick_place", "leap_hand")]
    # ... but Table III pools "w/ preview" and "W/ Preview": 12, 16, 14
    assert leap.with_ == Summary(pytest.approx(14.0), pytest.approx(2.0), 3)
    assert leap.without == Summary(pytest.approx(23.0), pytest.approx(3.0), 3)
    assert leap.improvement_s == pytest.approx(-9.0)
    gripper = rows[("pick_place", "parallel_gripper")]
    assert gripper.without == Summary(17.0, None, 1) and gripper.with_.mean == pytest.approx(14.5)
    assert gripper.improvement_s == pytest.approx(-2.5)
    pour = rows[("pour", "leap_hand")]
    assert pour.without.mean is None and pour.improvement_s is None  # nothing to compare: missing
    assert set(rows) == {("pick_place", "leap_hand"), ("pick_place", "parallel_gripper"), ("pour", "leap_hand")}


def test_explicit_columns_replace_the_automatic_match(facts):
    # baseline as the "w/o preview" column: 30 and 40 against the preview sessions' 12, 16, 14
    rows = {(r.task, r.end_effector): r for r in table_iii(facts, ColumnMap(without_preview=("Baseline",)))}
    assert rows[("pick_place", "leap_hand")].without.mean == pytest.approx(35.0)
    assert rows[("pick_place", "leap_hand")].improvement_s == pytest.approx(14.0 - 35.0)
    assert rows[("pick_place", "parallel_gripper")].without.mean is None  # "without preview" no longer matches
    with pytest.raises(ConfigError, match="both"):
        ColumnMap(("baseline",), ("Baseline ",))


@pytest.mark.parametrize(
    "text, column",
    [
        ("w/ preview", "with"),
        ("With Preview", "with"),
        ("W/  PREVIEW", "with"),
        ("preview", "with"),
        ("w/o preview", "without"),
        ("w/o-preview", "without"),
        ("no preview", "without"),
        ("Without preview", "without"),
        ("baseline", None),
        ("", None),
        ("preview v2", None),
    ],
)
def test_conditions_map_to_table_iii_columns(text, column):
    assert preview_column(text) == column


def test_study_cli_prints_and_writes_tables_and_plots(paths, tmp_path):
    out = tmp_path / "out"
    run = teleprev("study", *paths, paths[0], "--out", out, columns=250)
    assert run.returncode == 0, run.stderr
    text = run.stdout
    assert "Table III" in text and "23.0 ± 3.0" in text and "14.0 ± 2.0" in text and "-9.0" in text
    assert "no survey" in text and "b.mcap" in text  # reported as missing
    assert "practice without a ready key" in text and "g.mcap" in text
    assert "d.mcap episode 2" in text  # the successful episode that was never stopped

    md = (out / "table_iii.md").read_text()
    assert "| LeapHand (16-DoF) | 23.0 ± 3.0 | 14.0 ± 2.0 | -9.0 |" in md
    assert "| Parallel-jaw Gripper (1-DoF) | 17.0 ± n/a | 14.5 ± 0.7 | -2.5 |" in md
    assert "task pour" in md and "| LeapHand (16-DoF) | n/a | 50.0 ± n/a | n/a |" in md

    rows = {(r["condition"], r["end_effector"]): r for r in csv.DictReader((out / "study.csv").open())}
    assert len(rows) == 6
    w = rows[("w/ preview", "leap_hand")]
    assert float(w["practice_time_mean_s"]) == pytest.approx(110.0) and w["practice_time_n"] == "2"
    g = rows[("with preview", "parallel_gripper")]
    assert g["mental_demand_mean"] == "" and g["surveys"] == "0" and g["sessions_without_survey"] == "1"
    assert (
        rows[("w/o preview", "leap_hand")]["practice_time_mean_s"] == ""
        and rows[("w/o preview", "leap_hand")]["sessions"] == "3"
    )
    ex = {
        (r["condition"], r["end_effector"], r["task"]): r for r in csv.DictReader((out / "execution_time.csv").open())
    }
    assert float(ex[("w/o preview", "leap_hand", "pick_place")]["execution_time_mean_s"]) == pytest.approx(
        23.0
    )  # a.mcap counted once
    assert ex[("w/o preview", "leap_hand", "pick_place")]["execution_time_n"] == "3"
    assert ex[("without preview", "parallel_gripper", "pick_place")]["execution_time_std_s"] == ""
    assert float(ex[("w/ preview", "leap_hand", "pour")]["execution_time_mean_s"]) == pytest.approx(50.0)
    t3 = list(csv.DictReader((out / "table_iii.csv").open()))
    leap = next(r for r in t3 if (r["task"], r["end_effector"]) == ("pick_place", "leap_hand"))
    assert float(leap["improvement_s"]) == pytest.approx(-9.0) and leap["with_n"] == "3"
    for png in ("likert.png", "practice_time.png"):
        assert (out / png).stat().st_size > 10_000 and (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_study_cli_task_filter_and_no_data(paths, tmp_path):
    out = tmp_path / "out"
    run = teleprev("study", paths[-1], "--out", out)
    assert run.returncode == 0, run.stderr
    assert "likert.png not written" in run.stdout and "practice_time.png not written" in run.stdout
    assert not (out / "likert.png").exists()
    run = teleprev("study", paths[-1], "--task", "pick_place", columns=80)
    assert (
        run.returncode == 2
        and "--task" in run.stderr
        and "'pick_place'" in run.stderr
        and "their tasks: pour" in run.stderr
    )
