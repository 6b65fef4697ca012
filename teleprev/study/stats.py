"""What a user study measures, from recorded sessions.

Per session: participant, condition, end effector, task, whether it was practice and, if so, the
practice time (from the practice start to the participant's "ready" key); every episode's execution time
(start to stop) and outcome (y/f keys); the questionnaire, if answered. Missing data stays missing
(None), never zero.

Aggregated per (condition, end effector): execution time of successful, kept episodes (mean, std, n),
success rate over episodes with an outcome, practice time, and each Likert dimension.

Conditions map to Table III's columns by their text: "w/ preview", "with preview" -> with preview;
"w/o preview", "without preview", "no preview" -> without preview (case and spacing ignored); other
conditions (e.g. "baseline") appear in the tables but not in Table III. `--with-preview` /
`--without-preview` name the conditions explicitly.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleprev.session import topics
from teleprev.session.reader import SessionReader
from teleprev.study import survey
from teleprev.study.questionnaire import KEYS


@dataclass(frozen=True)
class EpisodeFacts:
    index: int
    task: str
    duration_s: float | None
    outcome: str | None
    discarded: bool


@dataclass(frozen=True)
class SessionFacts:
    path: Path
    participant: str
    condition: str
    end_effector: str
    task: str
    practice: bool
    practice_time_s: float | None
    episodes: tuple[EpisodeFacts, ...]
    answers: dict[str, int] | None


def session_facts(path: str | Path) -> SessionFacts:
    path = Path(path)
    reader = SessionReader(path)
    meta = reader.metadata
    s = meta.get("session", {})
    practice = s.get("practice", "false") == "true"
    practice_time = None
    if practice and topics.OPERATOR in reader.topics:
        start = ready = None
        for msg in reader.messages([topics.OPERATOR]):
            event = msg.payload.data.get("event")
            if event == "practice_start" and start is None:
                start = msg.payload.stamp_ns
            elif event == "ready" and ready is None:
                ready = msg.payload.stamp_ns
        if ready is not None:
            practice_time = (ready - (start if start is not None else reader.start_ns)) / 1e9
    episodes = tuple(EpisodeFacts(e.index, e.task, e.duration_s, e.outcome, e.discarded) for e in reader.episodes())
    return SessionFacts(
        path, s.get("participant", ""), s.get("condition", ""), s.get("end_effector", meta.get("rig", {}).get("end_effector", "")),
        s.get("task", ""), practice, practice_time, episodes, survey.load(path, meta),
    )


def preview_column(condition: str, with_label: str | None = None, without_label: str | None = None) -> str | None:
    """"with" / "without" (preview) for Table III, or None for any other condition."""
    if with_label is not None and condition == with_label:
        return "with"
    if without_label is not None and condition == without_label:
        return "without"
    key = re.sub(r"[^a-z/]", "", condition.lower())
    if key in ("w/opreview", "withoutpreview", "nopreview", "wopreview"):
        return "without"
    if key in ("w/preview", "withpreview", "preview", "wpreview"):
        return "with"
    return None


@dataclass(frozen=True)
class Summary:
    """mean, std (population-free: sample std with n-1, 0 for one value), n; None when n == 0."""

    mean: float | None
    std: float | None
    n: int

    @classmethod
    def of(cls, values) -> "Summary":
        v = np.asarray([x for x in values if x is not None], dtype=float)
        if len(v) == 0:
            return cls(None, None, 0)
        return cls(float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0, len(v))

    def text(self, digits: int = 1) -> str:
        return "n/a" if self.mean is None else f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"


@dataclass(frozen=True)
class Group:
    condition: str
    end_effector: str
    sessions: int
    execution_time_s: Summary  # successful, kept episodes
    success_rate: float | None  # over kept episodes with an outcome
    episodes_with_outcome: int
    practice_time_s: Summary
    likert: dict[str, Summary] = field(default_factory=dict)
    surveys: int = 0


def group(sessions: list[SessionFacts], task: str | None = None) -> list[Group]:
    """Per (condition, end effector), in the order they first appear."""
    keys = list(dict.fromkeys((s.condition, s.end_effector) for s in sessions))
    out = []
    for condition, ee in keys:
        members = [s for s in sessions if (s.condition, s.end_effector) == (condition, ee)]
        kept = [e for s in members if not s.practice for e in s.episodes if not e.discarded and (task is None or e.task == task)]
        judged = [e for e in kept if e.outcome in ("success", "failure")]
        success = [e for e in judged if e.outcome == "success"]
        surveyed = [s.answers for s in members if s.answers is not None]
        out.append(Group(
            condition, ee, len(members),
            Summary.of(e.duration_s for e in success),
            len(success) / len(judged) if judged else None, len(judged),
            Summary.of(s.practice_time_s for s in members if s.practice),
            {k: Summary.of(a[k] for a in surveyed) for k in KEYS}, len(surveyed),
        ))
    return out


@dataclass(frozen=True)
class TableIIIRow:
    end_effector: str
    without: Summary
    with_: Summary
    improvement_s: float | None  # with - without (negative: faster with preview)


def table_iii(groups: list[Group], with_label: str | None = None, without_label: str | None = None) -> list[TableIIIRow]:
    rows = []
    for ee in dict.fromkeys(g.end_effector for g in groups):
        cols = {preview_column(g.condition, with_label, without_label): g for g in groups if g.end_effector == ee}
        if "with" not in cols and "without" not in cols:
            continue
        wo = cols["without"].execution_time_s if "without" in cols else Summary(None, None, 0)
        w = cols["with"].execution_time_s if "with" in cols else Summary(None, None, 0)
        improvement = w.mean - wo.mean if w.mean is not None and wo.mean is not None else None
        rows.append(TableIIIRow(ee, wo, w, improvement))
    return rows
