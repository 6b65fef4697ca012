"""Asking the questionnaire and keeping the answers with the session, without touching the recording.

The answers go in a JSON sidecar next to the session, the one the session's metadata names
(study.survey_sidecar); it is written whole or not at all (a temporary file renamed into place), and an
existing survey is never replaced unless asked to.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from pathlib import Path
from typing import Callable

from teleprev.errors import ConfigError, SessionError
from teleprev.study.questionnaire import KEYS, QUESTIONS, VERSION, parse_answer  # noqa: F401 (KEYS, QUESTIONS re-exported)


def sidecar_path(session: Path, metadata: dict | None = None) -> Path:
    if metadata is None:
        from teleprev.session.reader import SessionReader

        metadata = SessionReader(session).metadata
    name = metadata.get("study", {}).get("survey_sidecar") or session.with_suffix(".survey.json").name
    return session.parent / name


def parse_answers(text: str) -> dict[str, int]:
    """'3,2,4,3,5' -> the five answers in questionnaire order; ConfigError naming the bad one."""
    parts = [p for p in text.replace(" ", "").split(",")]
    if len(parts) != len(QUESTIONS):
        raise ConfigError(f"expected {len(QUESTIONS)} answers separated by commas ({', '.join(KEYS)}), got {len(parts)}", "--answers")
    out = {}
    for q, part in zip(QUESTIONS, parts):
        try:
            out[q.key] = parse_answer(part)
        except ValueError as exc:
            raise ConfigError(f"{q.key}: {exc}", "--answers") from None
    return out


def ask(prompt: Callable[[str], str], say: Callable[[str], None]) -> dict[str, int]:
    """Ask every question, re-asking until the answer is valid."""
    answers = {}
    for n, q in enumerate(QUESTIONS, start=1):
        while True:
            raw = prompt(f"{n}. {q.text}  (1 = {q.low}, 5 = {q.high}): ")
            try:
                answers[q.key] = parse_answer(raw)
                break
            except ValueError as exc:
                say(str(exc))
    return answers


def store(session: Path, answers: dict[str, int], replace: bool = False) -> Path:
    """Write the sidecar; nothing is written if anything is wrong."""
    from teleprev.session.reader import SessionReader

    meta = SessionReader(session).metadata  # also checks that the session is readable
    path = sidecar_path(session, meta)
    if path.exists() and not replace:
        raise SessionError(f"a survey is already stored in {path.name}; pass --replace to answer again", str(session))
    if set(answers) != set(KEYS) or not all(isinstance(v, int) and 1 <= v <= 5 for v in answers.values()):
        raise ConfigError(f"a survey needs the five answers {', '.join(KEYS)}, each 1-5, got {answers}", str(session))
    s = meta.get("session", {})
    record = {
        "questionnaire": VERSION,
        "session": session.name,
        "participant": s.get("participant", ""),
        "condition": s.get("condition", ""),
        "answered": _dt.datetime.now().isoformat(timespec="seconds"),
        "answers": {k: answers[k] for k in KEYS},
    }
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=2))
    os.replace(tmp, path)
    return path


def load(session: Path, metadata: dict | None = None) -> dict[str, int] | None:
    """The stored answers, or None when the session has no survey."""
    path = sidecar_path(session, metadata)
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        answers = {k: int(data["answers"][k]) for k in KEYS}
    except (ValueError, KeyError, TypeError) as exc:
        raise SessionError(f"the survey file is damaged ({exc})", str(path)) from None
    return answers
