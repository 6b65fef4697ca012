"""The post-condition questionnaire of the TelePreview paper (appendix F, Table IV): five 1-5 Likert items."""

from __future__ import annotations

from dataclasses import dataclass

VERSION = "telepreview-table-iv"


@dataclass(frozen=True)
class Question:
    key: str
    label: str  # short name for tables and plots
    text: str
    low: str  # the anchor of 1
    high: str  # the anchor of 5
    higher_is_better: bool = False


QUESTIONS: tuple[Question, ...] = (
    Question("mental_demand", "Mental demand", "How mentally demanding was the task?", "Very Low", "Very High"),
    Question("physical_demand", "Physical demand", "How physically demanding was the task?", "Very Low", "Very High"),
    Question("frustration", "Frustration", "How frustrated did you feel while using the system?", "Not at all", "Extremely"),
    Question("overall_effort", "Overall effort", "How much overall effort did the task require?", "Very Little", "Very Much"),
    Question("perceived_success", "Perceived success", "How successful do you feel you were in completing the tasks?",
             "Very Unsuccessful", "Very Successful", higher_is_better=True),
)
KEYS = tuple(q.key for q in QUESTIONS)


def parse_answer(text: str) -> int:
    """A Likert answer: an integer from 1 to 5, or ValueError saying what is wrong."""
    value = text.strip()
    if not value.isdigit() or not 1 <= int(value) <= 5:
        raise ValueError(f"{text.strip()!r} is not an answer: type a whole number from 1 to 5")
    return int(value)
