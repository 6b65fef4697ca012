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


@pytest.mark.parametrize("damage", ["truncated", "header flipped", "empty"])
def test_eval_with_unreadable_weights_is_refused_once_before_the_work(tmp_path, damage):
    """It evaluated every session, each failing on the weights, and exited 1 with nothing on stderr."""
    from tests.cli.test_mistakes import one_line
    from tests.helpers.cli import teleprev

    models = tmp_path / "models"
    shutil.copytree(Path(__file__).parents[2] / "models", models)
    weights = models / "cpn_leap_hand.safetensors"
    data = bytearray(weights.read_bytes())
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "header flipped":
        data[12] ^= 0xFF
    else:
        data = bytearray()
    weights.write_bytes(bytes(data))
    run = teleprev("eval", FIXTURE, "--models", models, "--out", tmp_path / "report.json")
    line = one_line(run)
    assert run.returncode == 2 and f"{weights}: not a readable safetensors file" in line, line
    assert not (tmp_path / "report.json").exists()
