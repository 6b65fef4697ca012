"""Which recorded episodes an export takes: by outcome mark, task, participant and condition, and a
held-out split of them. Decided from the sessions' episode events and metadata alone (nothing is
written, lerobot is not imported), so a selection that matches nothing is refused before any export.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, replace
from pathlib import Path

from teleprev.errors import ConfigError
from teleprev.export.repo_id import check_repo_id
from teleprev.topics import TASKS_RECORD

OUTCOMES = ("success", "failure", "unmarked")
SPLITS = ("session", "episode")


@dataclass(frozen=True)
class EpisodeFacts:
    """What a selection and the dataset's per-episode metadata know of one recorded episode."""

    session: str  # the session file as given
    index: int
    task: str  # the task id
    instruction: str  # the task as LeRobot gets it (the id without an instruction)
    outcome: str  # "success", "failure" or "" (unmarked)
    participant: str
    condition: str
    discarded: bool

    @property
    def key(self) -> tuple[str, int]:
        return self.session, self.index


def episode_facts(reader, path: Path) -> list[EpisodeFacts]:
    """The episodes of an open session (a SessionReader) with the session's participant and condition."""
    meta = reader.metadata
    session = meta.get("session", {})
    instructions = meta.get(TASKS_RECORD, {})
    out = []
    for ep in reader.episodes():
        task = ep.task or session.get("task", "") or "teleoperation"
        out.append(EpisodeFacts(str(path), ep.index, task, instructions.get(task, task), ep.outcome or "",
                                session.get("participant", ""), session.get("condition", ""), ep.discarded))
    return out


def read_facts(paths: list[Path]) -> list[EpisodeFacts]:
    from teleprev.session.reader import SessionReader

    facts = []
    for path in paths:
        with SessionReader(path) as reader:
            facts += episode_facts(reader, path)
    return facts


@dataclass(frozen=True)
class Selection:
    only: str | None = None  # success | failure | unmarked
    task: str | None = None  # a task id or its instruction
    participant: str | None = None
    condition: str | None = None

    def __post_init__(self):
        if self.only is not None and self.only not in OUTCOMES:
            raise ConfigError(f"--only must be {', '.join(OUTCOMES)}, got {self.only!r}")

    def filters(self) -> list[tuple[str, object]]:
        """(label, predicate) per filter given, in the order they apply."""
        out = []
        if self.only is not None:
            wanted = "" if self.only == "unmarked" else self.only
            out.append((f"--only {self.only}", lambda f: f.outcome == wanted))
        if self.task is not None:
            out.append((f"--task {self.task}", lambda f: self.task in (f.task, f.instruction)))
        if self.participant is not None:
            out.append((f"--participant {self.participant}", lambda f: f.participant == self.participant))
        if self.condition is not None:
            out.append((f"--condition {self.condition}", lambda f: f.condition == self.condition))
        return out


@dataclass
class Selected:
    kept: list[EpisodeFacts]
    counts: list[tuple[str, int]]  # ("recorded", n) then (filter label, episodes left after it)


def select(facts: list[EpisodeFacts], selection: Selection, include_discarded: bool = False) -> Selected:
    """The episodes every filter keeps (discarded ones only with `include_discarded`); refuses a selection
    that keeps none, naming the filter that emptied it."""
    kept = [f for f in facts if include_discarded or not f.discarded]
    counts = [("recorded", len(kept))]
    for label, keeps in selection.filters():
        kept = [f for f in kept if keeps(f)]
        counts.append((label, len(kept)))
        if not kept:
            found = sorted({_value(label, f) for f in facts}) if facts else []
            raise ConfigError(f"{label} matches no episode of the {counts[0][1]} recorded"
                              + (f" ({label.split()[0]} values there: {', '.join(found)})" if found else ""))
    return Selected(kept, counts)


def _value(label: str, f: EpisodeFacts) -> str:
    flag = label.split()[0]
    return {"--only": f.outcome or "unmarked", "--task": f.task, "--participant": f.participant or "(none)",
            "--condition": f.condition or "(none)"}[flag]


def split(
    kept: list[EpisodeFacts], fraction: float, by: str, seed: int
) -> tuple[list[EpisodeFacts], list[EpisodeFacts]]:
    """(main, holdout): round(fraction x the sessions or episodes) of them held out, drawn by `seed`
    (the same seed and input give the same split); each part keeps the recorded order."""
    if not 0.0 < fraction < 1.0:
        raise ConfigError(f"--holdout must be a fraction between 0 and 1, got {fraction}")
    if by not in SPLITS:
        raise ConfigError(f"--split-by must be {' or '.join(SPLITS)}, got {by!r}")
    units = sorted({f.session for f in kept}) if by == "session" else sorted(f.key for f in kept)
    count = round(fraction * len(units))
    if count == 0 or count == len(units):
        raise ConfigError(f"--holdout {fraction} of {len(units)} {by}s holds out {count}: both datasets need at least "
                          f"one {by}")
    held = set(random.Random(seed).sample(units, count))
    unit = (lambda f: f.session) if by == "session" else (lambda f: f.key)
    return [f for f in kept if unit(f) not in held], [f for f in kept if unit(f) in held]


def by_session(kept: list[EpisodeFacts]) -> dict[str, frozenset[int]]:
    """session -> the indices of its episodes that are kept (what the export is told)."""
    out: dict[str, set[int]] = {}
    for f in kept:
        out.setdefault(f.session, set()).add(f.index)
    return {s: frozenset(i) for s, i in out.items()}


def plan_exports(options, selection, holdout: float | None, split_by: str, seed: int) -> tuple[list, dict[str, int]]:
    """The export(s) a selection and a held-out split make, and how many episodes each filter kept.
    Every refusal (nothing selected, a split that leaves a side empty, a target that is there or, with
    --append, is not) comes before either dataset is written."""
    chosen = select(read_facts(options.sessions), selection, options.include_discarded)
    counts = dict(chosen.counts)
    if holdout is None:
        return [
            replace(options, selected=by_session(chosen.kept), sessions=_with(options.sessions, chosen.kept))
        ], counts
    main, held = split(chosen.kept, holdout, split_by, seed)
    held_id = f"{options.repo_id}_holdout"
    check_repo_id(held_id)
    held_root = Path(options.root).parent / f"{Path(options.root).name}_holdout"
    for where in (Path(options.root), held_root):
        there = where.exists() and (not where.is_dir() or any(where.iterdir()))
        if options.append and not there:
            raise ConfigError("--append with --holdout: there is no dataset here to append to (neither is written)",
                              str(where))
        if not options.append and there:
            raise ConfigError("already exists; pass --append to add these sessions to it, or choose another --root "
                              "(neither dataset is written)", str(where))
    return [replace(options, selected=by_session(main), sessions=_with(options.sessions, main)),
            replace(options, repo_id=held_id, root=held_root, selected=by_session(held),
                    sessions=_with(options.sessions, held))], counts


def _with(sessions: list, kept) -> list:
    """The sessions that have an episode in `kept`, in their order."""
    having = {f.session for f in kept}
    return [p for p in sessions if str(p) in having]
