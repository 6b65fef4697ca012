"""Timed episodes on real sim sessions (LiveSession, the file read back with SessionReader): boundaries
where the plan puts them, the robot at rest by each episode's end and sent nothing during resets, marks,
cues, the countdown on screen, the plan kept in the file and shown by `teleprev info`, and the keys n, d,
a and space during a timed run."""

from __future__ import annotations

import io
import os
import threading
import time

import numpy as np
from rich.console import Console

from teleprev import topics
from teleprev.live.record.cues import Cues
from teleprev.live.record.run import RESTING, TimedKeys, run_timed
from teleprev.live.record.schedule import EpisodeTimes
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.session.reader import SessionReader
from tests.helpers.cli import teleprev
from tests.helpers.sessions import record_what_is_sent
from tests.helpers.wait import wait_until
from tests.live.test_schedule import fake_speech


def test_a_timed_plan_runs_to_its_times(tmp_path, monkeypatch):
    said = fake_speech(tmp_path)
    monkeypatch.setenv("PATH", f"{tmp_path}{os.pathsep}{os.environ['PATH']}")
    plan = EpisodeTimes(3, 1.5, 1.0, engage_after_s=0.2, marks="yf-")
    path = tmp_path / "timed.mcap"
    rec = LiveSession(RecordOptions(out=path, episode_plan=plan))
    sent = record_what_is_sent(rec)
    screen = io.StringIO()
    console = Console(file=screen, width=80, height=24, force_terminal=True, color_system=None)
    bell = io.StringIO()
    rec.start()
    try:
        assert rec.wait_connected() == []
        stats = run_timed(rec, plan, console, cues=Cues(bell, Cues.for_terminal(None).speech))
    finally:
        rec.stop()
    assert stats.frames > 0

    with SessionReader(path) as reader:
        episodes = reader.episodes()
        events = [m for m in reader.messages([topics.EPISODE])]
        modes = [(m.log_time_ns, m.payload.data) for m in reader.messages([topics.MODE])]
        arm = [m.payload for m in reader.messages([topics.COMMAND_ARM])]
        assert reader.metadata["episode_plan"]["marks"] == "yf-"

    # boundaries: planned from the first start, stamped where the plan puts them (not where a busy loop got)
    t0 = episodes[0].start_ns
    assert [(e.start_ns - t0, e.stop_ns - t0) for e in episodes] == [
        (0, 1_500_000_000), (2_500_000_000, 4_000_000_000), (5_000_000_000, 6_500_000_000)]
    assert all(0 <= m.log_time_ns - m.payload.stamp_ns < 1_000_000_000 for m in events)
    assert [e.outcome for e in episodes] == ["success", "failure", None] and not any(e.discarded for e in episodes)

    # the robot: engaged in the episodes, at rest by each end, nothing sent during the resets
    engaged = [e for e in episodes if any(m["mode"] == "execute" and e.start_ns <= t < e.stop_ns for t, m in modes)]
    assert engaged, modes
    for e in engaged:
        inside = [c for c in arm if e.start_ns <= c.stamp_ns <= e.stop_ns]
        assert inside and not np.any(inside[-1].velocities), (e, inside[-1])
    resets = [(a.stop_ns, b.start_ns) for a, b in zip(episodes, episodes[1:])]
    to_session = lambda mono_s: rec.clock.from_monotonic(round(mono_s * 1e9))  # noqa: E731
    for port in sent.values():
        assert port.sent, "nothing was sent"
        assert not [t for t, _ in port.sent if any(a <= to_session(t) <= b for a, b in resets)]
    assert not [c for c in arm if any(a <= c.stamp_ns <= b for a, b in resets)]

    # cues at every boundary, the countdown on screen, the plan in `info`
    assert said.read_text().splitlines() == ["episode 1", "reset", "episode 2", "reset", "episode 3", "done"]
    assert bell.getvalue() == "\a" * 6
    text = screen.getvalue()
    assert "episode 1/3:" in text and "reset:" in text and "s left" in text
    info = teleprev("info", path)
    assert info.returncode == 0, info.stderr
    line = next(ln for ln in info.stdout.splitlines() if "episode plan" in ln)
    assert line.split() == "episode plan 3 x 1.5 s, resets 1 s, engage after 0.2 s, marks yf-".split()


def test_keys_during_timed_episodes(tmp_path):
    """n ends the current period (episode -> reset, reset -> next episode), space in a reset is refused in
    one line, a discards the running episode and records it again, d in a reset discards the last one;
    each stamped when the key came."""
    plan = EpisodeTimes(3, 1.5, 1.0)
    path = tmp_path / "keys.mcap"
    rec = LiveSession(RecordOptions(out=path, episode_plan=plan))
    keys = TimedKeys(rec.clock)
    pressed, refusal = {}, []
    snap = lambda: rec.loop.snapshot  # noqa: E731

    def operator():
        wait_until(lambda: snap().episode == 0 and snap().episode_active, what="episode 0 running")
        time.sleep(0.3)
        pressed["n1"] = keys.press("n")  # episode 0 ends now
        wait_until(lambda: not snap().episode_active, what="the reset")
        pressed["space"] = keys.press(" ")
        wait_until(lambda: "cannot switch to execute" in snap().message, what="the refusal")
        refusal.append(snap().message)
        pressed["n2"] = keys.press("n")  # the reset ends now: episode 1 starts
        wait_until(lambda: snap().episode == 1 and snap().episode_active, what="episode 1 running")
        time.sleep(0.3)
        pressed["a"] = keys.press("a")  # episode 1 discarded, recorded again after the reset
        wait_until(lambda: snap().episode == 2 and snap().episode_active, what="episode 2 running")
        wait_until(lambda: not snap().episode_active, what="the reset")  # its natural end: the reset
        pressed["d"] = keys.press("d")  # discards episode 2

    rec.start()
    helper = threading.Thread(target=operator, daemon=True)
    try:
        assert rec.wait_connected() == []
        helper.start()
        run_timed(rec, plan, cues=Cues(None, None), keys=keys)
    finally:
        helper.join(15)
        rec.stop()
    assert not helper.is_alive()
    assert refusal == [f"cannot switch to execute: {RESTING}"]
    with SessionReader(path) as reader:
        ep = reader.episodes()
        switches = (
            [m.payload.data["mode"] for m in reader.messages([topics.MODE])] if topics.MODE in reader.topics else []
        )
    assert "execute" not in switches  # the refused space engaged nothing
    assert [e.discarded for e in ep] == [False, True, True, False]
    assert ep[0].stop_ns == pressed["n1"]
    assert ep[1].start_ns == pressed["n2"] and ep[1].stop_ns == pressed["a"]
    assert ep[2].start_ns == pressed["a"] + 1_000_000_000 and ep[2].stop_ns == ep[2].start_ns + 1_500_000_000
    assert ep[3].start_ns == ep[2].stop_ns + 1_000_000_000 and ep[3].stop_ns == ep[3].start_ns + 1_500_000_000
    assert ep[2].stop_ns < pressed["d"] < ep[3].start_ns


def test_record_runs_timed_episodes_from_the_command_line(tmp_path):
    run = teleprev("record", "--episodes", "2", "--episode-time", "0.8", "--reset-time", "0.4", "--marks", "f",
                   "--no-preview", "-o", tmp_path / "cli.mcap", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    with SessionReader(tmp_path / "cli.mcap") as reader:
        plan = EpisodeTimes.from_record(reader.metadata["episode_plan"])
        episodes = reader.episodes()
    assert plan == EpisodeTimes(2, 0.8, 0.4, None, "f")
    assert [(e.duration_s, e.outcome) for e in episodes] == [(0.8, "failure"), (0.8, "failure")]
    assert episodes[1].start_ns - episodes[0].stop_ns == 400_000_000
