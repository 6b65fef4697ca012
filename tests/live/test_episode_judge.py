"""A physics world that cannot judge a stopping episode does not cost the session its episode events: the
stop and the next start are recorded all the same, so the file reads back (it did not, when a world process
died while the loop stopped an episode: "'stop' for episode 1, which never started")."""

from __future__ import annotations

from pathlib import Path

from teleprev.live.core.controls import StartEpisode, StopEpisode
from teleprev.live.core.episodes import EpisodeTracker
from teleprev.messages import Event, Logged
from teleprev.session.episodes import episodes_from


def _world_gone():
    raise RuntimeError("the physics world process exited")


def test_a_judge_that_fails_leaves_every_episode_event_in_place():
    tracker, logged, t = EpisodeTracker(), [], 0
    for control in (StartEpisode("pick_place"), StartEpisode("pick_place"), StopEpisode()):
        t += 1_000
        events, message = tracker.apply_judged(control, t, _world_gone)
        logged += [Logged("/events/episode", t, Event(t, "teleprev.EpisodeEvent", e)) for e in events]
        if isinstance(control, StartEpisode) and tracker.index == 0:
            assert message == ""
        else:
            assert "could not judge it (RuntimeError: the physics world process exited)" in message
    episodes = episodes_from(logged, Path("s.mcap"))
    assert [(e.index, e.start_ns, e.stop_ns) for e in episodes] == [(0, 1_000, 2_000), (1, 2_000, 3_000)]
    assert all(e.judged is None for e in episodes)
