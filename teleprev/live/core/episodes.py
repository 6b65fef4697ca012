"""Episodes inside a session: start, stop, discard, outcome, each as a teleprev.EpisodeEvent."""

from __future__ import annotations

from dataclasses import dataclass

from teleprev.live.core.controls import DiscardEpisode, MarkOutcome, StartEpisode, StopEpisode


@dataclass
class EpisodeTracker:
    index: int = -1  # the current (or last) episode; -1 before the first
    active: bool = False
    task: str = ""
    started_ns: int = 0

    def apply(self, control: StartEpisode | StopEpisode | DiscardEpisode | MarkOutcome, t_ns: int) -> list[dict]:
        """The events of an episode control carried out at t_ns (a start without a task: the last one's)."""
        if isinstance(control, StartEpisode):
            return self.start(control.task or self.task or "", t_ns)
        if isinstance(control, StopEpisode):
            return self.stop(t_ns)
        if isinstance(control, DiscardEpisode):
            return self.discard(t_ns)
        return self.outcome(control.success)

    def start(self, task: str, t_ns: int) -> list[dict]:
        """Events that start a new episode (stopping the running one first)."""
        events = self.stop(t_ns)
        self.index += 1
        self.active, self.task, self.started_ns = True, task, t_ns
        return events + [{"event": "start", "episode": self.index, "task": task}]

    def stop(self, t_ns: int) -> list[dict]:
        if not self.active:
            return []
        self.active = False
        return [{"event": "stop", "episode": self.index, "task": self.task}]

    def discard(self, t_ns: int) -> list[dict]:
        """Discard the running episode (stopping it), or the last one if none is running."""
        if self.index < 0:
            return []
        return self.stop(t_ns) + [{"event": "discard", "episode": self.index, "task": self.task}]

    def outcome(self, success: bool) -> list[dict]:
        """The operator's mark of the running (or last) episode."""
        if self.index < 0:
            return []
        return [
            {
                "event": "outcome",
                "episode": self.index,
                "task": self.task,
                "outcome": "success" if success else "failure",
            }
        ]

    def apply_judged(self, control, t_ns: int, judge) -> tuple[list[dict], str]:
        """apply, with each episode that stops marked by `judge` (a physics rig's outcome now, as (mark,
        reason), or None) beside the operator's y/f; and the operator's message about it ("": none)."""
        stopping = self.task
        events = self.apply(control, t_ns)
        message = ""
        if judge is not None:
            for stop in [e for e in events if e["event"] == "stop"]:
                try:
                    judged = judge()
                except Exception as exc:  # noqa: BLE001 - the episode's own events are recorded all the same
                    judged = None
                    message = (f"episode {stop['episode'] + 1} ({stopping}): the physics world could not judge it "
                               f"({type(exc).__name__}: {exc})")
                if judged is not None:
                    mark, reason = judged
                    events.insert(events.index(stop) + 1, self.judged(stop["episode"], stopping, mark, reason))
                    message = (f"episode {stop['episode'] + 1} ({stopping}): {mark.upper()}, "
                               f"by the physics world: {reason}")
        return events, message

    @staticmethod
    def judged(index: int, task: str, mark: str, reason: str) -> dict:
        """The physics world's mark of episode `index` (judged when it stopped), beside the operator's."""
        return {"event": "outcome", "episode": index, "task": task, "outcome": mark, "source": "physics",
                "reason": reason}

    def elapsed_s(self, now_ns: int) -> float:
        return (now_ns - self.started_ns) / 1e9 if self.active else 0.0
