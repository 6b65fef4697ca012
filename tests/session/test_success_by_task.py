"""Each task's success rate over a session's episodes (teleprev/session/episodes.py: success_by_task), as
lerobot-eval's pc_success: kept episodes with an outcome count, the operator's mark over the world's."""

from __future__ import annotations

from pathlib import Path

from teleprev.messages import Event, Logged
from teleprev.session.episodes import episodes_from, success_by_task
from teleprev.topics import EPISODE


def _events(*data: dict) -> list[Logged]:
    return [Logged(EPISODE, i, Event(i, "teleprev.EpisodeEvent", d)) for i, d in enumerate(data)]


def test_rates_per_task_count_kept_judged_episodes_and_the_operators_mark_wins():
    episodes = episodes_from(_events(
        {"event": "start", "episode": 0, "task": "pick_place"},
        {"event": "stop", "episode": 0, "task": "pick_place"},
        {"event": "outcome", "episode": 0, "outcome": "failure", "source": "physics", "reason": "cup tilted"},
        {"event": "outcome", "episode": 0, "outcome": "success"},  # the operator's y wins
        {"event": "start", "episode": 1, "task": "pick_place"},
        {"event": "stop", "episode": 1, "task": "pick_place"},
        {"event": "outcome", "episode": 1, "outcome": "failure", "source": "physics", "reason": "cup tilted"},
        {"event": "start", "episode": 2, "task": "pour"},
        {"event": "stop", "episode": 2, "task": "pour"},
        {"event": "outcome", "episode": 2, "outcome": "success", "source": "physics", "reason": "10 balls"},
        {"event": "discard", "episode": 2, "task": "pour"},  # discarded: not counted
        {"event": "start", "episode": 3, "task": "pour"},
        {"event": "stop", "episode": 3, "task": "pour"},  # never judged: counted, not rated
    ), Path("s.mcap"))
    rates = success_by_task(episodes)
    assert list(rates) == ["pick_place", "pour"]
    pick, pour = rates["pick_place"], rates["pour"]
    assert (pick.episodes, pick.judged, pick.successes, pick.pc_success) == (2, 2, 1, 50.0)
    assert (pour.episodes, pour.judged, pour.successes, pour.pc_success) == (1, 0, 0, None)
