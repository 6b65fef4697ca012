"""An MCAP written by another tool is not a teleprev session: every command that takes a session refuses it
in one line naming the file and the program that wrote it (it was read as a session "never engaged",
and some commands went on with it). teleprev's writer puts a "teleprev" metadata record in every file;
`teleprev import` still reads foreign files (SessionReader(any_mcap=True))."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from teleprev.errors import SessionError
from teleprev.session.reader import SessionReader
from tests.helpers.cli import teleprev

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"
REFUSAL = "not a teleprev session: an MCAP file written by othertool 1.0"


@pytest.fixture(scope="module")
def foreign(tmp_path_factory) -> Path:
    """A complete, valid MCAP from another program: a JSON pose topic and a "session" metadata record (a
    name teleprev uses too)."""
    from mcap.writer import Writer

    path = tmp_path_factory.mktemp("foreign") / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="othertool 1.0")
        channel = w.register_channel("/pose", "json", w.register_schema("pose", "jsonschema", b"{}"))
        for k in range(50):
            w.add_message(channel, 1_000 + k * 10_000_000, json.dumps({"x": k}).encode(), 1_000 + k * 10_000_000)
        w.add_metadata("session", {"task": "pick_place"})
        w.finish()
    return path


def test_the_reader_refuses_it_and_still_reads_teleprevs_own(foreign):
    with pytest.raises(SessionError, match=REFUSAL):
        SessionReader(foreign)
    with SessionReader(foreign, any_mcap=True) as reader:  # what `teleprev import` opens
        assert reader.topics["/pose"].message_count == 50
    with SessionReader(FIXTURE) as reader:
        assert reader.metadata["teleprev"]["format_version"]


@pytest.mark.parametrize("command", [
    ["info"], ["audit"], ["replay"], ["recover"], ["survey"], ["study"], ["eval"],
    ["export", "--repo-id", "lab/foreign"],
])
def test_every_session_command_refuses_it_in_one_line(foreign, tmp_path, command):
    extra = ["--root", tmp_path / "ds"] if command[0] == "export" else []
    ran = teleprev(*command, foreign, *extra)
    said = " ".join((ran.stdout + ran.stderr).split())
    assert ran.returncode in (1, 2) and REFUSAL in said, (ran.returncode, ran.stdout, ran.stderr)
    if command[0] != "eval":  # eval reports each session it could not evaluate in its table, exit 1
        assert ran.returncode == 2 and len(ran.stderr.strip().splitlines()) == 1, ran.stderr
    assert not (tmp_path / "ds").exists() and not foreign.with_suffix(".recovered.mcap").exists()
