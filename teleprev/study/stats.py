"""Aggregating a study: per (condition, end effector), and the paper's Table III.

Per group (an input condition on an end effector, as in the paper's appendix D):
- per task (the episode's task label): execution time of successful, kept (not discarded) episodes of
  non-practice sessions, start to stop, mean ± sample std (n-1) over episodes; success rate over the kept
  episodes marked y/f (unmarked ones are counted apart, not as failures);
- practice time over the group's practice sessions with a ready key;
- each Likert dimension over the group's surveys (one per condition, whatever task it followed).
A summary of no values is missing (None), never zero; a std of one value is missing too.

Table III (per task: end effector x w/o preview, w/ preview, improvement = w/ - w/o) needs to know which
conditions are "w/ preview" and which "w/o preview". A condition's text, lower-cased with everything but
letters, digits and "/" removed, maps to
    w/ preview:  "w/preview", "wpreview", "withpreview", "preview", "previewon"
    w/o preview: "w/opreview", "wopreview", "withoutpreview", "nopreview", "previewoff"
so "W/ Preview", "with preview" and "w/o  preview" all match. Other conditions (e.g. "baseline") are in
the per-group table but not in Table III. `--with-preview TEXT` / `--without-preview TEXT` name a column's
conditions explicitly (case and surrounding spaces ignored) and replace the automatic match for that
column. Conditions mapping to the same column are pooled.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from teleprev.errors import ConfigError
from teleprev.study.facts import SessionFacts
from teleprev.study.questionnaire import KEYS

WITH, WITHOUT = "with", "without"
_AUTO = {WITH: {"w/preview", "wpreview", "withpreview", "preview", "previewon"},
         WITHOUT: {"w/opreview", "wopreview", "withoutpreview", "nopreview", "previewoff"}}


@dataclass(frozen=True)
class Summary:
    mean: float | None
    std: float | None  # sample std (n-1); None for fewer than two values
    n: int

    @classmethod
    def of(cls, values) -> Summary:
        v = np.asarray([x for x in values if x is not None], dtype=float)
        if len(v) == 0:
            return cls(None, None, 0)
        return cls(float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else None, len(v))

    def text(self, digits: int = 1) -> str:
        """Like the paper: "23.6 ± 4.7"; "n/a" when missing."""
        if self.mean is None:
            return "n/a"
        std = "n/a" if self.std is None else f"{self.std:.{digits}f}"
        return f"{self.mean:.{digits}f} ± {std}"


@dataclass(frozen=True)
class TaskStats:
    task: str
    execution_time_s: Summary  # successful, kept episodes
    success_rate: float | None  # over kept episodes with an outcome
    judged: int  # kept episodes marked success or failure
    unmarked: int  # kept episodes without an outcome: in neither execution time nor success rate


@dataclass(frozen=True)
class Group:
    condition: str
    end_effector: str
    sessions: int
    participants: int
    tasks: dict[str, TaskStats]  # by task, in the order they first appear; empty without episodes
    practice_sessions: int
    practice_time_s: Summary  # practice sessions with a ready key
    surveys: int = 0
    not_surveyed: int = 0  # non-practice sessions without a survey
    likert: dict[str, Summary] = field(default_factory=dict)


def _kept(sessions: list[SessionFacts], task: str | None = None):
    """Kept episodes of non-practice sessions, with their task (the episode's label, else the session's)."""
    out = []
    for s in sessions:
        if not s.practice:
            out += [(e.task or s.task, e) for e in s.episodes if not e.discarded]
    return [(t, e) for t, e in out if task is None or t == task]


def _task_stats(task: str, episodes) -> TaskStats:
    judged = [e for e in episodes if e.outcome in ("success", "failure")]
    success = [e for e in judged if e.outcome == "success"]
    return TaskStats(task, Summary.of(e.duration_s for e in success), len(success) / len(judged) if judged else None,
                     len(judged), len(episodes) - len(judged))


def group(sessions: list[SessionFacts], task: str | None = None) -> list[Group]:
    """One Group per (condition, end effector), in the order they first appear; `task` keeps one task's episodes."""
    out = []
    for condition, ee in dict.fromkeys((s.condition, s.end_effector) for s in sessions):
        members = [s for s in sessions if (s.condition, s.end_effector) == (condition, ee)]
        kept = _kept(members, task)
        tasks = {t: _task_stats(t, [e for u, e in kept if u == t]) for t in dict.fromkeys(t for t, _ in kept)}
        practice = [s for s in members if s.practice]
        surveyed = [s.answers for s in members if s.answers is not None]
        out.append(Group(
            condition, ee, sessions=len(members), participants=len({s.participant for s in members}), tasks=tasks,
            practice_sessions=len(practice), practice_time_s=Summary.of(s.practice_time_s for s in practice),
            surveys=len(surveyed), not_surveyed=sum(s.answers is None and not s.practice for s in members),
            likert={k: Summary.of(a[k] for a in surveyed) for k in KEYS},
        ))
    return out


def _norm(text: str) -> str:
    return re.sub(r"[^a-z0-9/]", "", text.lower())


@dataclass(frozen=True)
class ColumnMap:
    """Which conditions are Table III's "w/ preview" and "w/o preview" columns."""

    with_preview: tuple[str, ...] = ()  # explicit condition texts; empty: automatic match
    without_preview: tuple[str, ...] = ()

    def __post_init__(self):
        both = {c.strip().lower() for c in self.with_preview} & {c.strip().lower() for c in self.without_preview}
        if both:
            raise ConfigError(
                f"condition {sorted(both)[0]!r} is named both --with-preview and --without-preview", "teleprev study"
            )

    def column(self, condition: str) -> str | None:
        c = condition.strip().lower()
        explicit = {
            WITH: {x.strip().lower() for x in self.with_preview},
            WITHOUT: {x.strip().lower() for x in self.without_preview},
        }
        for col in (WITH, WITHOUT):
            if c in explicit[col]:
                return col
        for col in (WITH, WITHOUT):
            if not explicit[col] and _norm(condition) in _AUTO[col]:
                return col
        return None


def preview_column(condition: str) -> str | None:
    """"with" / "without" (preview) by the automatic match, or None for any other condition."""
    return ColumnMap().column(condition)


@dataclass(frozen=True)
class TableIIIRow:
    task: str
    end_effector: str
    without: Summary
    with_: Summary
    improvement_s: float | None  # with - without: negative when faster with preview


def table_iii(
    sessions: list[SessionFacts], columns: ColumnMap = ColumnMap(), task: str | None = None
) -> list[TableIIIRow]:
    """A row per (task, end effector) with episodes in either preview column."""
    placed: dict[tuple[str, str], dict[str, list]] = {}  # (task, end effector) -> column -> episodes
    for s in sessions:
        col = columns.column(s.condition)
        if col is not None:
            for t, e in _kept([s], task):
                placed.setdefault((t, s.end_effector), {WITH: [], WITHOUT: []})[col].append(e)
    rows = []
    for (t, ee), cols in placed.items():
        w, wo = (_task_stats(t, cols[c]).execution_time_s for c in (WITH, WITHOUT))
        improvement = w.mean - wo.mean if w.mean is not None and wo.mean is not None else None
        rows.append(TableIIIRow(t, ee, wo, w, improvement))
    return rows


def pooled_conditions(sessions: list[SessionFacts], columns: ColumnMap) -> dict[str, list[str]]:
    """For the report: which condition texts went into each Table III column."""
    out: dict[str, list[str]] = {WITHOUT: [], WITH: []}
    for c in dict.fromkeys(s.condition for s in sessions):
        col = columns.column(c)
        if col:
            out[col].append(c)
    return out
