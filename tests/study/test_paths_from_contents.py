"""Paths taken from a session's contents (its metadata, the rig it carries) never direct a write, and are
refused when they lead out of the session's folder; a rig file's own write paths stay in its folder."""

from __future__ import annotations

import hashlib

import pytest

from teleprev.errors import ConfigError
from teleprev.rig import default_rig_path, load_recorded_rig
from tests.helpers.cli import teleprev
from tests.helpers.faults import has_traceback
from tests.helpers.study_sessions import scripted


def crafted(path, **meta):
    """A study session whose metadata is then rewritten with `meta` (as a hostile file would be)."""
    from teleprev import topics
    from teleprev.messages import Event, Logged
    from teleprev.session.reader import SessionReader
    from teleprev.session.writer import McapSessionWriter

    records = {"session": {"participant": "p1", "condition": "w/ preview", "end_effector": "leap_hand",
                           "task": "pick_place", "practice": "false"}}
    records.update(meta)
    with McapSessionWriter(path, records) as w:
        w.write(
            Logged(topics.MODE, 10**12, Event(10**12, "teleprev.ModeSwitch", {"mode": "preview", "reason": "start"}))
        )
    with SessionReader(path) as reader:
        assert reader.metadata["session"]["participant"] == "p1"
    return path


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_survey_replace_never_writes_where_the_metadata_points(tmp_path):
    victim = scripted(tmp_path / "victim.mcap", "w/ preview", "leap_hand", episodes=((3.0, "success", False),))
    before = digest(victim)
    session = crafted(tmp_path / "crafted.mcap", study={"survey_sidecar": "victim.mcap"})
    for replace in ([], ["--replace"]):
        run = teleprev("survey", session, "--answers", "1,2,3,4,5", *replace)
        assert run.returncode == 0 and not has_traceback(run.stdout + run.stderr), run.stderr
    assert digest(victim) == before  # the other recording is untouched
    assert (tmp_path / "crafted.survey.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["crafted.mcap", "crafted.survey.json", "victim.mcap"]


@pytest.mark.parametrize("key, value, message", [
    ("models", "../../elsewhere/models", "leads out of"),
    ("models", "/opt/models", "leads out of"),
    ("calibration", "../calib/x.toml", "leads out of"),
    ("robot", "/tmp/evil.urdf", "is a path"),
])
def test_a_recorded_rig_is_confined_to_its_sessions_folder(tmp_path, key, value, message):
    import re

    text = re.sub(rf"(?m)^{key} = .*$", "", default_rig_path().read_text())
    text = text.replace("[rig]\n", f"[rig]\n{key} = {value!r}\n", 1)
    meta = {"rig": {"toml": text, "path": "/somewhere/else/rig.toml"}}
    with pytest.raises(ConfigError, match=message):
        load_recorded_rig(meta, tmp_path / "s.mcap")
    session = crafted(tmp_path / f"{key}.mcap", rig=meta["rig"])
    run = teleprev("audit", session)
    assert run.returncode == 2 and message in run.stderr and not has_traceback(run.stderr), run.stderr


def test_a_recorded_rig_is_anchored_at_the_session_not_at_the_path_it_names(tmp_path):
    text = default_rig_path().read_text()
    rig = load_recorded_rig({"rig": {"toml": text, "path": "/somewhere/else/rig.toml"}}, tmp_path / "s.mcap")
    assert rig.dir == tmp_path.resolve()


def test_replay_to_the_arm_needs_a_rig_from_the_user(tmp_path):
    session = crafted(tmp_path / "r.mcap", rig={"toml": default_rig_path().read_text(), "path": ""})
    run = teleprev("replay", session, "--to", "arm")
    assert run.returncode == 2 and "--to arm needs --rig" in run.stderr, run.stderr


def test_a_rig_files_truth_log_stays_in_its_folder(tmp_path):
    from teleprev.rig import load_rig

    rig = tmp_path / "rig.toml"
    rig.write_text(
        default_rig_path()
        .read_text()
        .replace('plugin = "sim.glove"', 'plugin = "sim.glove"\ntruth_log = "../x.mcap"', 1)
    )
    with pytest.raises(ConfigError, match="truth_log must be a path inside"):
        load_rig(rig)
