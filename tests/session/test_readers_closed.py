"""Every command closes the session files it opens: once `info`, `audit`, `eval`, `replay` and `import` have
read a session (or refused it), no descriptor or memory map of the file is left in the process and no
unclosed file was left for the garbage collector (a ResourceWarning). An eval of a corpus in one process
would otherwise pile up open files and mappings."""

from __future__ import annotations

import gc
import os
import shutil
import warnings
from contextlib import contextmanager
from pathlib import Path

import pytest

from teleprev.errors import SessionError

FIXTURE_V2 = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"


def handles_on(path: Path) -> int:
    """Descriptors and memory mappings of this process that point at `path`."""
    target = os.path.realpath(path)
    fds = 0
    for fd in os.listdir("/proc/self/fd"):
        try:
            fds += os.readlink(f"/proc/self/fd/{fd}") == target
        except OSError:  # the descriptor listing the folder itself, gone by now
            pass
    with open("/proc/self/maps") as maps:
        mapped = sum(1 for line in maps if line.rstrip().endswith(" " + target))
    return fds + mapped


@contextmanager
def nothing_left_open(path: Path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ResourceWarning)
        yield
        gc.collect()  # a reader nobody closed is collected here: its file warns as it goes
    unclosed = [
        str(w.message) for w in caught if issubclass(w.category, ResourceWarning) and path.name in str(w.message)
    ]
    assert not unclosed, unclosed
    assert handles_on(path) == 0


@pytest.fixture
def session(tmp_path) -> Path:
    """A copy of the format-2 fixture (rig and all) that nothing else in this process has opened."""
    out = tmp_path / "s.mcap"
    shutil.copyfile(FIXTURE_V2, out)
    return out


def test_the_probe_sees_a_reader_left_open(session):
    from teleprev.session.reader import SessionReader

    reader = SessionReader(session)
    assert handles_on(session) >= 2  # the file and its memory map
    with pytest.raises(AssertionError):
        with nothing_left_open(session):
            del reader  # dropped without close(): the collector closes it, with a warning
    assert handles_on(session) == 0


def test_info_closes_the_session(session):
    from teleprev.session.summary import summarize

    with nothing_left_open(session):
        summarize(session)


def test_audit_closes_the_session(session):
    from teleprev.evaluation.audit import audit_session

    with nothing_left_open(session):
        audit_session(session)


def test_eval_closes_the_session(session):
    from teleprev.evaluation.evaluate import evaluate

    with nothing_left_open(session):
        assert evaluate([session]).report["sessions"][0]["episodes"]


def test_replay_closes_the_session(session):
    from teleprev.live.replay.playback import build_player

    with nothing_left_open(session):
        build_player(session, 0, 1.0, "preview")


def test_a_refused_episode_closes_the_session(session):
    from teleprev.live.replay.player import load_playback

    with nothing_left_open(session):
        with pytest.raises(SessionError, match="no episode 7"):
            load_playback(session, 7)


def test_a_foxglove_import_refused_at_its_metadata_closes_the_file(session):
    """A damaged metadata record fails after the file is open: the reader is closed on the way out."""
    from teleprev.export.foreign.config import load_import_recipe
    from teleprev.export.foreign.foxglove import FoxgloveReader
    from teleprev.session import records as mr

    with open(session, "rb") as f:
        summary = mr.read_summary(f, session.stat().st_size)
    _, offset, _ = summary.metadata[0]
    data = bytearray(session.read_bytes())
    data[offset] = 0  # the record's opcode: not a metadata record any more
    session.write_bytes(bytes(data))
    recipe = load_import_recipe("foxglove_arm")
    with nothing_left_open(session):
        with pytest.raises(SessionError, match="metadata record"):
            FoxgloveReader(session, recipe)
