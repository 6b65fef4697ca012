"""A session's episodes, from its /events/episode messages: start, stop, discard and outcome by index."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from teleprev.errors import SessionError
from teleprev.messages import Event, Logged
from teleprev.topics import EPISODE


@dataclass(frozen=True, slots=True)
class Episode:
    """An episode as its /events/episode messages describe it; times are the events' stamp_ns.
    `stop_ns` is None when the session ended (or was cut short) before the episode was stopped.
    `outcome` is the operator's mark where there is one, else the physics world's (`judged`, with its
    `judged_reason`): what exports and statistics select by."""

    index: int
    task: str
    start_ns: int
    stop_ns: int | None
    discarded: bool
    outcome: str | None
    marked: str | None = None  # the operator's own mark (y / f)
    judged: str | None = None  # the physics world's, when the episode stopped
    judged_reason: str = ""

    @property
    def duration_s(self) -> float | None:
        return None if self.stop_ns is None else (self.stop_ns - self.start_ns) / 1e9


def episodes_from(messages: Iterable[Logged], path: Path) -> list[Episode]:
    """Episodes from the /events/episode messages of the session at `path`, in log time order."""
    found: dict[int, dict] = {}
    for msg in messages:
        ev = msg.payload
        if not isinstance(ev, Event):
            raise SessionError(f"{EPISODE} holds {type(ev).__name__} messages, expected episode events",
                               str(path))
        kind, index = ev.data.get("event"), ev.data.get("episode")
        where = f"{EPISODE} at log time {msg.log_time_ns}"
        if not isinstance(index, int):
            raise SessionError(f"{where}: episode index {index!r} is not an integer", str(path))
        ep = found.get(index)
        if kind == "start":
            if ep is not None:
                raise SessionError(f"{where}: episode {index} started twice", str(path))
            found[index] = {"index": index, "task": str(ev.data.get("task") or ""), "start_ns": ev.stamp_ns,
                            "stop_ns": None, "discarded": False, "outcome": None, "marked": ev.data.get("outcome"),
                            "judged": None, "judged_reason": ""}
            continue
        if ep is None:
            raise SessionError(f"{where}: {kind!r} for episode {index}, which never started", str(path))
        if kind == "stop":
            ep["stop_ns"] = ev.stamp_ns
        elif kind == "discard":
            ep["discarded"] = True
            if ep["stop_ns"] is None:
                ep["stop_ns"] = ev.stamp_ns
        elif kind == "outcome" and ev.data.get("source") == "physics":
            ep["judged"], ep["judged_reason"] = ev.data.get("outcome"), str(ev.data.get("reason") or "")
        elif kind == "outcome":
            ep["marked"] = ev.data.get("outcome")
        else:
            raise SessionError(f"{where}: unknown episode event {kind!r}", str(path))
        if ev.data.get("task") and not ep["task"]:
            ep["task"] = str(ev.data["task"])
    for ep in found.values():
        ep["outcome"] = ep["marked"] or ep["judged"]
    return [Episode(**found[i]) for i in sorted(found)]


@dataclass(frozen=True, slots=True)
class TaskSuccess:
    """One task's episodes and how many of them succeeded, as lerobot-eval reports `pc_success`: kept
    (not discarded) episodes with an outcome count, the operator's mark over the physics world's."""

    task: str
    episodes: int  # kept episodes of the task
    judged: int  # of those, the ones with an outcome
    successes: int

    @property
    def pc_success(self) -> float | None:
        """Per cent of the judged episodes that succeeded; None when none was judged."""
        return 100.0 * self.successes / self.judged if self.judged else None


def success_by_task(episodes: Iterable[Episode]) -> dict[str, TaskSuccess]:
    """Each task's TaskSuccess, tasks in the order their first episode came."""
    counts: dict[str, list[int]] = {}
    for ep in episodes:
        if ep.discarded:
            continue
        c = counts.setdefault(ep.task, [0, 0, 0])
        c[0] += 1
        c[1] += ep.outcome is not None
        c[2] += ep.outcome == "success"
    return {task: TaskSuccess(task, *c) for task, c in counts.items()}
