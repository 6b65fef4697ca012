"""Every output option of every command is checked before the work starts (teleprev/cli/outputs.py): a
folder where a file goes, a file where a folder goes, a path under a file, a missing folder, a read-only
one: one line naming the option, exit 2, in about a second."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest

from tests.cli.test_mistakes import one_line
from tests.helpers.cli import teleprev

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"


def layout(tmp: Path) -> dict[str, Path]:
    (tmp / "a_folder").mkdir()
    (tmp / "a_file").write_text("x")
    return {"folder": tmp / "a_folder", "under a file": tmp / "a_file" / "out.json", "file": tmp / "a_file",
            "missing folder": tmp / "missing" / "out.json", "deep under a file": tmp / "a_file" / "x" / "out.json"}


# (command before the path, the option, after the path, which bad path, what the line says)
CASES = {
    "record --out folder": (
        ["record", "--duration", "1", "--no-preview", "--out"],
        [],
        "folder",
        "--out",
        "is a folder",
    ),
    "record --out under a file": (
        ["record", "--duration", "1", "--no-preview", "--out"],
        [],
        "deep under a file",
        "--out",
        "is a file, not a folder",
    ),
    "rollout --out folder": (["rollout", "--policy", "nowhere", "--out"], [], "folder", "--out", "is a folder"),
    "replay --out folder": (["replay", FIXTURE, "--out"], [], "folder", "--out", "is a folder"),
    "replay --out under a file": (["replay", FIXTURE, "--out"], [], "under a file", "--out", "is a file, not a folder"),
    "replay --out missing folder": (["replay", FIXTURE, "--out"], [], "missing folder", "--out", "does not exist"),
    "eval --out folder": (["eval", FIXTURE, "--out"], [], "folder", "--out", "is a folder"),
    "eval --out missing folder": (["eval", FIXTURE, "--out"], [], "missing folder", "--out", "does not exist"),
    "eval --plots file": (["eval", FIXTURE, "--plots"], [], "file", "--plots", "is a file"),
    "eval --plots under a file": (
        ["eval", FIXTURE, "--plots"],
        [],
        "under a file",
        "--plots",
        "is a file, not a folder",
    ),
    "eval --baseline folder": (["eval", FIXTURE, "--baseline"], [], "folder", "--baseline", "is a folder"),
    "eval --baseline missing": (["eval", FIXTURE, "--baseline"], [], "missing folder", "--baseline", "no such report"),
    "audit --json folder": (["audit", FIXTURE, "--json"], [], "folder", "--json", "is a folder"),
    "audit --json under a file": (
        ["audit", FIXTURE, "--json"],
        [],
        "under a file",
        "--json",
        "is a file, not a folder",
    ),
    "audit --json missing folder": (["audit", FIXTURE, "--json"], [], "missing folder", "--json", "does not exist"),
    "study --out file": (["study", FIXTURE, "--out"], [], "file", "--out", "is a file"),
    # the collision commands: checked before the robot's checker is built and torch loads
    "collision dataset under a file": (["collision", "dataset"], ["--uniform", "10"], "deep under a file", "OUT",
                                       "is a file, not a folder"),
    "collision dataset file": (["collision", "dataset"], ["--uniform", "10"], "file", "OUT", "is a file"),
    "collision train-cpn --out folder": (["collision", "train-cpn", "a_folder", "--out"], [], "folder", "--out",
                                         "is a folder"),
    "collision train-ccn --out under a file": (["collision", "train-ccn", "a_folder", "--out"], [], "under a file",
                                               "--out", "is a file, not a folder"),
    "collision grid-search --out under a file": (["collision", "grid-search", "a_folder", "--out"], [],
                                                 "deep under a file", "--out", "is a file, not a folder"),
}


@pytest.mark.parametrize("case", CASES)
def test_a_bad_output_path_is_refused_before_the_work(tmp_path, case):
    before, after, which, option, said = CASES[case]
    path = layout(tmp_path)[which]
    started = time.monotonic()
    run = teleprev(*before, path, *after, cwd=tmp_path)
    line = one_line(run)
    assert run.returncode == 2 and option in line and said in line and str(path) in line, line
    assert time.monotonic() - started < 5, "refused only after the work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "a_folder"], "something was written"


@pytest.fixture
def read_only(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=4m", "tmpfs", str(folder)],
                             capture_output=True, text=True)
    # test.sh runs as root, as CI does: a read-only mount is how this test makes an unwritable folder
    assert mounted.returncode == 0, f"cannot mount a read-only tmpfs (needs root): {mounted.stderr.strip()}"
    yield folder
    subprocess.run(["umount", "-l", str(folder)], capture_output=True)


@pytest.mark.parametrize("args", [["record", "--duration", "1", "--no-preview", "--out"], ["audit", FIXTURE, "--json"],
                                  ["eval", FIXTURE, "--out"], ["calibrate", "--hold", "0.5", "--out"],
                                  ["collision", "dataset"], ["recover", FIXTURE, "--out"]],
                         ids=["record", "audit", "eval", "calibrate", "collision dataset", "recover"])
def test_a_read_only_folder_is_refused_before_the_work(read_only, args):
    run = teleprev(*args, read_only / "out.mcap")
    line = one_line(run)
    assert run.returncode == 2 and f"cannot write in {read_only}: it is read-only" in line, line


def test_a_survey_beside_a_session_in_a_read_only_folder_is_refused_before_the_questions(read_only, tmp_path):
    import shutil

    session = tmp_path / "s.mcap"
    shutil.copy(FIXTURE, session)
    subprocess.run(["mount", "-o", "remount,rw", str(read_only)], check=True)
    shutil.copy(FIXTURE, read_only / "s.mcap")
    subprocess.run(["mount", "-o", "remount,ro", str(read_only)], check=True)
    run = teleprev("survey", read_only / "s.mcap", "--answers", "3,2,4,3,5")
    line = one_line(run)
    assert run.returncode == 2 and "the survey beside the session" in line and "read-only" in line, line
