"""Asking the questionnaire and keeping the answers with the session, without touching the recording.

The answers go in a JSON sidecar next to the session under a fixed name, `<stem>.survey.json`. The name
is never taken from the session's contents (its metadata also names the sidecar, for people reading the
file): a crafted session must not be able to point the write at another file.

    {"questionnaire": "telepreview-table-iv", "scale": [1, 5],
     "session": "x.mcap", "session_start_ns": 1700000000000000000,
     "participant": "p07", "condition": "w/ preview", "end_effector": "leap_hand", "task": "pick_place",
     "answered": "2026-11-22T10:42:27+00:00",
     "answers": {"mental_demand": 2, "physical_demand": 3, "frustration": 1, "overall_effort": 2, "perceived_success":
     5}}

`session_start_ns` ties the answers to the recording (it survives renaming the file), so a sidecar copied
next to another session is refused instead of counted. The file is written whole or not at all (a
temporary file, synced, renamed into place), and a stored survey is only replaced when asked to.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import secrets
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from teleprev.errors import ConfigError, SessionError
from teleprev.study.questionnaire import KEYS, QUESTIONS, VERSION, parse_answer  # noqa: F401 (KEYS, QUESTIONS re-exported)


@dataclass(frozen=True)
class Target:
    """The session a survey belongs to, read once before asking anything."""

    session: Path
    sidecar: Path
    start_ns: int | None
    fields: dict[str, str]  # participant, condition, end_effector, task, practice from the session metadata


def target(session: str | os.PathLike) -> Target:
    from teleprev.session.reader import SessionReader

    session = Path(session)
    with SessionReader(session) as reader:
        meta, start_ns = reader.metadata, reader.start_ns
    s = meta.get("session", {})
    fields = {k: s.get(k, "") for k in ("participant", "condition", "end_effector", "task", "practice")}
    fields["end_effector"] = fields["end_effector"] or meta.get("rig", {}).get("end_effector", "")
    return Target(session, sidecar_path(session), start_ns, fields)


def sidecar_path(session: Path) -> Path:
    """`<stem>.survey.json` beside the session: fixed, never read from the session's metadata."""
    session = Path(session)
    return session.with_name(f"{session.stem}.survey.json")


def parse_answers(text: str) -> dict[str, int]:
    """'3,2,4,3,5' -> the five answers in questionnaire order; ConfigError naming the bad one."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != len(QUESTIONS):
        raise ConfigError(f"expected {len(QUESTIONS)} answers separated by commas, in the order {', '.join(KEYS)}; "
                          f"got {len(parts)}", "--answers")
    out = {}
    for n, (q, part) in enumerate(zip(QUESTIONS, parts), start=1):
        try:
            out[q.key] = parse_answer(part, q)
        except ValueError as exc:
            raise ConfigError(f"answer {n} ({q.key}): {exc}", "--answers") from None
    return out


def ask(prompt: Callable[[str], str], say: Callable[[str], None]) -> dict[str, int]:
    """Ask every question, re-asking until the answer is valid. EOFError/KeyboardInterrupt propagate."""
    answers = {}
    for n, q in enumerate(QUESTIONS, start=1):
        while True:
            raw = prompt(f"{n}/{len(QUESTIONS)}. {q.text}  (1 = {q.low} ... 5 = {q.high}): ")
            try:
                answers[q.key] = parse_answer(raw, q)
                break
            except ValueError as exc:
                say(str(exc))
    return answers


def check_free(t: Target, replace: bool) -> None:
    """Refuse before anything is asked when a survey is stored and may not be replaced."""
    if t.sidecar.exists() and not replace:
        raise SessionError(
            f"a survey is already stored in {t.sidecar.name}; pass --replace to answer again", str(t.session)
        )


def store(t: Target, answers: dict[str, int], replace: bool = False) -> Path:
    """Write the sidecar; nothing is written (and nothing stored changes) if anything is wrong."""
    check_free(t, replace)
    bad = set(answers) ^ set(KEYS)
    if bad or not all(type(answers[k]) is int and 1 <= answers[k] <= 5 for k in KEYS):
        raise ConfigError(f"a survey needs the five answers {', '.join(KEYS)}, each 1-5; got {answers}", str(t.session))
    record = {
        "questionnaire": VERSION,
        "scale": [1, 5],
        "session": t.session.name,
        "session_start_ns": t.start_ns,
        **{k: v for k, v in t.fields.items() if k != "practice"},
        "answered": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "answers": {k: answers[k] for k in KEYS},
    }
    tmp = t.sidecar.with_name(f".{t.sidecar.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, "x") as f:
            json.dump(record, f, indent=2)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, t.sidecar)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return t.sidecar


def load(t: Target) -> dict[str, int] | None:
    """The stored answers, or None when the session has no survey; SessionError if the file is unusable."""
    path = t.sidecar
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SessionError(f"the survey file cannot be read ({exc})", str(path)) from None
    if not isinstance(data, dict) or not isinstance(data.get("answers"), dict):
        raise SessionError("the survey file has no 'answers' object", str(path))
    if data.get("questionnaire", VERSION) != VERSION:
        raise SessionError(f"answers to questionnaire {data.get('questionnaire')!r}, not {VERSION!r}", str(path))
    owner = data.get("session_start_ns")
    if owner is not None and t.start_ns is not None and owner != t.start_ns:
        raise SessionError(
            f"the survey belongs to another recording ({data.get('session', '?')}), not {t.session.name}", str(path)
        )
    answers = {}
    for k in KEYS:
        v = data["answers"].get(k)
        if type(v) is not int or not 1 <= v <= 5:
            raise SessionError(f"answers.{k} is {v!r}, expected a whole number 1-5", str(path))
        answers[k] = v
    return answers
