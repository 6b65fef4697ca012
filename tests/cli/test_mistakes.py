"""A mistake on the command line gets one line naming it and a non-zero exit, before anything opens: no
device, no session file, no dataset folder."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from teleprev.errors import ConfigError
from teleprev.export.repo_id import check_repo_id
from teleprev.rig import default_rig_path, load_rig
from tests.helpers.cli import teleprev

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"


def one_line(run) -> str:
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    return lines[0]


def nothing_made(folder: Path) -> None:
    assert sorted(p.name for p in folder.iterdir()) == [], "a mistake left files behind"


@pytest.mark.parametrize("args, said", [
    (["record", "--view", "diagonal"], "'diagonal' is not one of 'front', 'side', 'top'"),
    (["record", "--task", "pickplace", "--duration", "5"], "did you mean 'pick_place'?"),
    (["record", "--episodes", "0", "--duration", "5"], "'--episodes'"),
    (["record", "--duration", "-3"], "--duration must be a positive number of seconds, got -3"),
    (["record", "--duration", "3", "--fps", "0"], "--fps must be more than 0 and at most 120"),
    (["record", "--duration", "3", "--fps", "nan"], "--fps must be more than 0 and at most 120"),
    (["record", "--duration", "3", "--fps", "1e9"], "--fps must be more than 0 and at most 120"),
    (["record", "--episode-time", "2", "--episodes", "0"], "'--episodes'"),
    (["record", "--episode-time", "-1"], "--episode-time must be a positive number of seconds, got -1"),
    (["record", "--episode-time", "2", "--reset-time", "nan"], "--reset-time must be 0 or more seconds, got nan"),
    (["record", "--episode-time", "2", "--marks", "yfx"], "--marks takes y (success), f (failure) and - (unmarked)"),
    (["record", "--episode-time", "2", "--engage-after", "2"], "less than --episode-time (2 s), got 2"),
    (["record", "--episode-time", "2", "--duration", "5"], "--episode-time and --duration both set"),
    (["record", "--reset-time", "1", "--duration", "5"], "--reset-time goes with --episode-time"),
    (["replay", FIXTURE, "--view", "diagonal"], "'diagonal' is not one of 'front', 'side', 'top'"),
    (["replay", FIXTURE, "--to", "robot"], "'robot' is not one of 'preview', 'sim', 'arm'"),
    (["replay", FIXTURE, "--to", "sim"], "pass --engage-after SECONDS"),  # no terminal to press space in
    (["export", FIXTURE, "--repo-id", "lab/x", "--codec", "vp9"], "'vp9' is not one of 'h264', 'hevc', 'av1'"),
    (["calibrate", "--out", "calib/ada.toml"], "pass --hold SECONDS"),  # no terminal to press Enter in
])
def test_refused_in_one_line_before_anything_opens(tmp_path, args, said):
    run = teleprev(*args, cwd=tmp_path)
    assert run.returncode == 2 and said in one_line(run)
    nothing_made(tmp_path)


@pytest.mark.parametrize("repo_id, said", [
    ("../x", "'..'"), ("", "empty"), ("lab/pick place", "'pick place'"), ("a/b/c", "more than one '/'"),
    ("lab/x.git", ".git"), ("-lab/x", "'-lab'"), ("lab/" + "x" * 97, "longer than 96"),
])
def test_a_dataset_name_the_hub_would_refuse_is_refused_before_anything_is_written(tmp_path, repo_id, said):
    for command in (["export", FIXTURE], ["import", FIXTURE, "--recipe", "foxglove_arm"]):
        run = teleprev(*command, "--repo-id", repo_id, cwd=tmp_path)
        assert run.returncode == 2 and said in one_line(run) and "--repo-id" in one_line(run)
        nothing_made(tmp_path)


def test_dataset_names_follow_the_hubs_own_check():
    from huggingface_hub.utils import HFValidationError, validate_repo_id

    names = ["lab/pick_place", "pick_place", "Foo-BAR_foo.bar123", "a/b", "1/2", "lab/x.y", "../x", "", "a/b/c",
             "lab/pick place", "lab/x.git", "-lab/x", "lab-/x", "lab/.x", "lab/x.", "a--b/c", "a/b..c", "a/", "/a",
             "lab/x" + "y" * 95, "lab/x" + "y" * 96, "x" * 97 + "/lab", "lab/ü", "lab/a+b", "lab\\x"]
    for name in names:
        try:
            validate_repo_id(name)
            hub_ok = name != ""  # the Hub's check lets "" through (it means "no repo"); as a name it is nothing
        except HFValidationError:
            hub_ok = False
        try:
            check_repo_id(name)
            ours_ok = True
        except ConfigError:
            ours_ok = False
        assert ours_ok == hub_ok, name


def test_a_rig_whose_task_the_sim_operator_does_not_know_is_refused_at_load(tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text(default_rig_path().read_text().replace('task = "pick_place"', 'task = "pickplace"', 1))
    with pytest.raises(ConfigError, match=r"rig.toml \[rig\].task: task 'pickplace' is not one device"):
        load_rig(rig)
    fixed = tmp_path / "fixed.toml"  # an operator with a task of its own ignores the episode's label
    fixed.write_text(re.sub(r'(?m)^task = ""', 'task = "pour"', default_rig_path().read_text()))
    load_rig(fixed).check_task("any label", "--task")


def test_help_shows_choices_and_no_type_labels_that_say_nothing():
    helps = {c: teleprev(*c.split(), "--help").stdout for c in
             ("record", "replay", "eval", "export", "import", "audit", "calibrate", "info", "survey", "study",
              "devices check", "collision dataset")}
    for command, text in helps.items():
        assert "<bool>" not in text and "<list[" not in text, command
    assert "<front|side|top>" in helps["record"] and "<front|side|top>" in helps["replay"]
    assert "<preview|sim|arm>" in helps["replay"] and "<h264|hevc|av1>" in helps["export"]
    assert "rig's [tasks] entry" in " ".join(helps["record"].split())  # not eaten as rich markup
    fps = " ".join(re.search(r"--fps.*?(?=│ +--)", helps["export"], re.S).group(0).split())
    assert "default: the recipe's" in fps and "[default: 0]" not in fps


def test_calibrate_refuses_an_out_it_could_not_write_before_the_first_pose(tmp_path):
    (tmp_path / "taken").write_text("a file where the folder should be")
    (tmp_path / "calib").mkdir()
    for out, said in ((tmp_path / "taken" / "ada.toml", "is a file, not a folder"),
                      (tmp_path / "calib", "is a folder")):
        run = teleprev("calibrate", "--out", out, "--hold", "0.5", cwd=tmp_path)
        assert run.returncode == 2 and said in one_line(run) and "ok" not in run.stdout  # no pose was taken
