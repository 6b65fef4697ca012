"""What one recorded session contributes to a user study.

Participant, condition, end effector and task come from the session metadata (set by `teleprev record`
options or the rig). Every episode's execution time is start to stop, its outcome the y/f key. A practice
session's practice time runs from its practice_start event (else the session's first message) to the
participant's first "ready" key after it. The survey is the sidecar the session names. Anything not
recorded is None, never zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from teleprev import topics
from teleprev.session.reader import SessionReader
from teleprev.study import survey


@dataclass(frozen=True)
class EpisodeFacts:
    index: int
    task: str
    duration_s: float | None  # None: never stopped (the session was cut short)
    outcome: str | None  # "success", "failure", or None when not marked
    discarded: bool


@dataclass(frozen=True)
class SessionFacts:
    path: Path
    participant: str
    condition: str
    end_effector: str
    task: str
    practice: bool
    practice_time_s: float | None  # None: not a practice session, or no ready key
    episodes: tuple[EpisodeFacts, ...]
    answers: dict[str, int] | None  # None: no survey


def practice_time_s(reader: SessionReader) -> float | None:
    if topics.OPERATOR not in reader.topics:
        return None
    start = ready = None
    for msg in reader.messages([topics.OPERATOR]):
        event = msg.payload.data.get("event")
        if event == "practice_start" and start is None:
            start = msg.payload.stamp_ns
        elif event == "ready" and ready is None and (start is None or msg.payload.stamp_ns >= start):
            ready = msg.payload.stamp_ns
            break
    if ready is None:
        return None
    return (ready - (start if start is not None else reader.start_ns)) / 1e9


def session_facts(path: str | Path) -> SessionFacts:
    path = Path(path)
    with SessionReader(path) as reader:
        meta = reader.metadata
        s = meta.get("session", {})
        practice = s.get("practice", "false") == "true"
        episodes = tuple(EpisodeFacts(e.index, e.task, e.duration_s, e.outcome, e.discarded) for e in reader.episodes())
        practice_s = practice_time_s(reader) if practice else None
        start_ns = reader.start_ns
    ee = s.get("end_effector") or meta.get("rig", {}).get("end_effector", "")
    task = s.get("task") or next((e.task for e in episodes if e.task), "")
    fields = {
        "participant": s.get("participant", ""),
        "condition": s.get("condition", ""),
        "end_effector": ee,
        "task": task,
    }
    answers = survey.load(survey.Target(path, survey.sidecar_path(path), start_ns, fields))
    return SessionFacts(
        path, fields["participant"], fields["condition"], ee, task, practice, practice_s, episodes, answers
    )
