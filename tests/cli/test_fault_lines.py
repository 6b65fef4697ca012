"""Faults that ended in a traceback, each now one line: the session's folder deleted while recording, a
replay recorded without --rig (the recorded rig has no file of its own)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from teleprev.errors import SessionError

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"


def test_a_deleted_folder_at_close_is_a_session_error(tmp_path):
    from teleprev.session.recorder import Recorder

    folder = tmp_path / "out"
    folder.mkdir()
    recorder = Recorder(folder / "s.mcap", {"session": {"task": "t"}}).start()
    shutil.rmtree(folder)
    with pytest.raises(SessionError, match="deleted while recording; the recording is lost"):
        recorder.close()


def test_the_recorded_rig_is_recorded_again_from_its_text():
    """`replay SESSION --to sim --out X` without --rig records the session's own rig in X's metadata."""
    from teleprev.live.record.metadata import rig_record
    from teleprev.rig import load_recorded_rig
    from teleprev.session.reader import SessionReader

    with SessionReader(FIXTURE) as reader:
        meta = reader.metadata
    rig = load_recorded_rig(meta, FIXTURE)
    assert not rig.path.exists()  # anchored beside the session, never written
    record = rig_record(rig)
    assert record["toml"] == meta["rig"]["toml"] and record["robot"] == meta["rig"]["robot"]
