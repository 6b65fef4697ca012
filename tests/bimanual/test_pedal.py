"""Without a keyboard: a USB foot pedal (a keyboard sending Page Down and Page Up) switches a bimanual session
between preview and execute and starts episodes, through the terminal's key reader on a real pseudo-terminal.
Escape sequences arrive whole: an arrow key is not read as Esc (which quits)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from teleprev.live.record.bimanual_session import open_session
from teleprev.live.record.operator_actions import handle_key
from teleprev.live.record.session import RecordOptions
from teleprev.preview.keys import KeyReader, keys_of
from teleprev.session.reader import SessionReader
from tests.helpers.wait import wait_until

RIG = Path(__file__).resolve().parents[2] / "rigs" / "sim_bimanual.toml"
PAGE_DOWN, PAGE_UP, UP, F5 = b"\x1b[6~", b"\x1b[5~", b"\x1b[A", b"\x1b[15~"


@pytest.fixture
def terminal():
    """(write, stream): bytes written at the terminal's end are what the key reader's stream reads."""
    master, slave = os.openpty()
    stream = os.fdopen(slave, "rb", buffering=0)
    try:
        yield (lambda data: os.write(master, data)), stream
    finally:
        stream.close()
        os.close(master)


def test_sequences_are_read_whole_and_only_the_pedals_keys_press_anything():
    assert keys_of("\x1b[6~") == [" "] and keys_of("\x1b[5~") == ["n"]
    assert keys_of("\x1b[A\x1bOP\x1b[15~") == []  # up arrow, F1, F5: dropped, no Esc among them
    assert keys_of("s\x1b") == ["s", "\x1b"]  # a lone Esc still quits
    assert keys_of("x\x1b[6~q") == ["x", " ", "q"]


def test_keys_from_a_real_terminal(terminal):
    write, stream = terminal
    got: list[str] = []
    with KeyReader(got.append, stream=stream) as reader:
        assert reader.is_terminal
        write(PAGE_DOWN + UP + b"s" + F5 + PAGE_UP)
        wait_until(lambda: len(got) >= 3, 5, what="three keys")
        write(b"\x1b")
        wait_until(lambda: len(got) >= 4, 5, what="a lone Esc")
    assert got == [" ", "s", "n", "\x1b"]


def test_a_pedal_engages_both_sides_and_starts_the_next_episode(terminal, tmp_path):
    write, stream = terminal
    out = tmp_path / "s.mcap"
    rec = open_session(RecordOptions(rig=RIG, out=out))
    quit_flag: list = []
    rec.start()
    try:
        def previewed():  # each side has stepped a while and has an arm target to engage to
            views = rec.loop.snapshot.sides
            return len(views) == 2 and all(v.step is not None and v.step.state.arm_q is not None
                                           and v.step.report.get("step", 0) >= 20 for v in views)
        wait_until(previewed, 30, what="both sides previewed")
        with KeyReader(lambda key: handle_key(rec, key, quit_flag), stream=stream):
            write(PAGE_DOWN)
            wait_until(lambda: rec.loop.snapshot.mode == "execute", 10, what="execute after Page Down")
            write(UP)  # a stray arrow key: no quit, no switch
            write(PAGE_UP)
            wait_until(lambda: rec.loop.snapshot.mode == "preview" and rec.loop.snapshot.episode_active, 10,
                       what="preview and an episode running after Page Up")
            write(PAGE_DOWN)
            wait_until(lambda: rec.loop.snapshot.mode == "execute", 10, what="execute again")
        assert not quit_flag
    finally:
        rec.stop()
    with SessionReader(out) as r:
        modes = [m.payload.data["mode"] for m in r.messages(topics=["/events/mode"])]
    assert modes.count("execute") == 2
