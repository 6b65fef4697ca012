"""The post-condition questionnaire of the TelePreview paper (appendix F, Table IV): five 1-5 Likert items."""

from __future__ import annotations

from dataclasses import dataclass

VERSION = "telepreview-table-iv"
SCALE = ("1", "2", "3", "4", "5")


@dataclass(frozen=True)
class Question:
    key: str
    label: str  # short name for tables and plots
    text: str  # the paper's wording
    low: str  # the anchor of 1
    high: str  # the anchor of 5
    higher_is_better: bool = False  # every item but perceived success: higher means more workload


QUESTIONS: tuple[Question, ...] = (
    Question("mental_demand", "Mental demand", "How mentally demanding was the task?", "Very Low", "Very High"),
    Question("physical_demand", "Physical demand", "How physically demanding was the task?", "Very Low", "Very High"),
    Question(
        "frustration", "Frustration", "How frustrated did you feel while using the system?", "Not at all", "Extremely"
    ),
    Question(
        "overall_effort", "Overall effort", "How much overall effort did the task require?", "Very Little", "Very Much"
    ),
    Question(
        "perceived_success",
        "Perceived success",
        "How successful do you feel you were in completing the tasks?",
        "Very Unsuccessful",
        "Very Successful",
        higher_is_better=True,
    ),
)
KEYS = tuple(q.key for q in QUESTIONS)


def parse_answer(text: str, question: Question | None = None) -> int:
    """A Likert answer: exactly one of the digits 1-5, or ValueError saying what is expected."""
    value = text.strip()
    if value not in SCALE:
        anchors = f" (1 = {question.low}, 5 = {question.high})" if question else ""
        raise ValueError(f"{value!r} is not an answer: type a whole number from 1 to 5{anchors}")
    return int(value)
