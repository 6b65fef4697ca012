"""Timed episodes' schedule: every boundary planned from the plan's start (no drift however many periods),
an early end anchors the rest there, a re-recorded episode repeats its number, no reset after the last;
the stop-time bound the preview switch leans on holds for the hardest stop; cues never wait."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from teleprev.errors import ConfigError
from teleprev.live.record.cues import Cues
from teleprev.live.record.schedule import EpisodeTimes, Schedule
from teleprev.pipeline.trajectory import ArmGenerator, HandLimiter, JointMotion


def periods(schedule: Schedule) -> list[tuple[str, int, int, int]]:
    out = []
    while schedule.current is not None:
        c = schedule.current
        out.append((c.kind, c.number, c.start_ns, c.end_ns))
        schedule.advance()
    return out


def test_boundaries_are_planned_from_the_start_and_do_not_drift():
    # 0.1 s and 0.7 s are not exact in binary: summed period by period they would drift
    plan = EpisodeTimes(1000, 0.1, 0.7).check()
    got = periods(Schedule(plan, 5_000_000_000))
    assert len(got) == 1999 and got[-1][0] == "episode"  # no reset after the last episode
    for i, (kind, number, start, end) in enumerate(got):
        assert kind == ("episode" if i % 2 == 0 else "reset") and number == i // 2
        assert start == 5_000_000_000 + i // 2 * 800_000_000 + i % 2 * 100_000_000  # to the nanosecond
    assert got[-1][3] == 5_000_000_000 + 799_300_000_000
    assert all(a[3] == b[2] for a, b in zip(got, got[1:]))


def test_an_early_end_anchors_the_rest_and_a_redo_repeats_the_episode():
    s = Schedule(EpisodeTimes(2, 2.0, 1.0), 0)
    s.advance(at_ns=500_000_000)  # episode 1 ended early: its reset gets its full second
    assert (s.current.kind, s.current.start_ns, s.current.end_ns) == ("reset", 500_000_000, 1_500_000_000)
    s.redo()  # the episode just ended is recorded again
    got = periods(s)
    assert [(k, n) for k, n, _, _ in got] == [("reset", 0), ("episode", 0), ("reset", 0), ("episode", 1)]
    assert got[1][2:] == (1_500_000_000, 3_500_000_000) and got[-1][3] == 6_500_000_000


@pytest.mark.parametrize("kwargs, said", [
    ({"episodes": 0, "episode_s": 1.0}, "--episodes must be 1 or more"),
    ({"episodes": 2, "episode_s": -1.0}, "--episode-time must be a positive"),
    ({"episodes": 2, "episode_s": float("inf")}, "--episode-time must be a positive"),
    ({"episodes": 2, "episode_s": 1.0, "reset_s": float("nan")}, "--reset-time must be 0 or more seconds, got nan"),
    ({"episodes": 2, "episode_s": 1.0, "engage_after_s": 1.0}, "less than --episode-time"),
    ({"episodes": 2, "episode_s": 1.0, "marks": "y+"}, "got '+'"),
])
def test_a_bad_plan_names_its_option(kwargs, said):
    with pytest.raises(ConfigError) as caught:
        EpisodeTimes(**kwargs).check()
    assert said in str(caught.value)


def test_marks_cycle_and_the_plan_reads_back_from_its_record():
    plan = EpisodeTimes(5, 1.5, 1.0, 0.3, "yf-")
    assert [plan.mark(k) for k in range(5)] == [True, False, None, True, False]
    assert EpisodeTimes.from_record(plan.to_record(0.4)) == plan
    assert EpisodeTimes(2, 1.0).mark(0) is None


def test_the_stop_time_bound_covers_the_hardest_stop():
    """From the speed cap while accelerating as hard as allowed (the worst state), the planner's stop
    comes to rest within the bound; so does the hand's."""
    n = 6
    limits = dict(lower=np.full(n, -100.0), upper=np.full(n, 100.0), velocity=np.full(n, 2.14),
                  acceleration=np.full(n, 10.0), jerk=np.full(n, 500.0))
    arm = ArmGenerator(**limits)
    bound = arm.stop_time_bound()
    assert 0.25 < bound < 0.3  # 3 a/j + (v + a^2/2j) / a = 0.06 + 0.224
    m, dt, t = JointMotion(np.zeros(n), np.full(n, 2.14), np.full(n, 10.0)), 1 / 120, 0.0
    while not m.at_rest:
        m, t = arm.stop(m, dt), t + dt
        assert t < 2.0
    assert 0.5 * bound < t <= bound + dt, (t, bound)
    hand = HandLimiter(np.full(16, -10.0), np.full(16, 10.0), np.full(16, 6.0), np.full(16, 200.0))
    q, v, t = np.zeros(16), np.full(16, 6.0), 0.0
    while v.any():
        q, v = hand.stop(q, v, dt, dt)
        t += dt
        assert t < 1.0
    assert t <= hand.stop_time_bound() + dt


def fake_speech(folder, seconds: float = 0.0):
    """A `spd-say` that appends its arguments to a file (after `seconds`)."""
    script = folder / "spd-say"
    said = folder / "said.txt"
    script.write_text(f'#!/bin/sh\nsleep {seconds}\necho "$@" >> "{said}"\n')
    script.chmod(0o755)
    return said


def test_cues_ring_and_speak_in_the_background(tmp_path, monkeypatch):
    import io

    said = fake_speech(tmp_path, seconds=0.5)
    monkeypatch.setenv("PATH", f"{tmp_path}{os.pathsep}{os.environ['PATH']}")
    bell = io.StringIO()
    cues = Cues(bell, Cues.for_terminal(None).speech)
    assert cues.speech == str(tmp_path / "spd-say")
    t = time.perf_counter()
    cues.cue("episode 2")
    cues.cue("reset")
    assert time.perf_counter() - t < 0.2  # the speech command takes half a second: nothing waits for it
    cues.close(timeout_s=5.0)  # (a session waits at most half a second)
    assert bell.getvalue() == "\a\a"
    assert said.read_text().splitlines() == ["episode 2", "reset"]
