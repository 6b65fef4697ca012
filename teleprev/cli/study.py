"""`teleprev survey` and `teleprev study`: the questionnaire after a condition, and the study's tables."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def survey(
    session: Path = typer.Argument(..., help="The session the participant just finished (.mcap)."),
    answers: Optional[str] = typer.Option(None, "--answers", help="Scripted: the five answers 1-5, e.g. 3,2,4,3,5."),
    replace: bool = typer.Option(False, "--replace", help="Replace a survey already stored for this session."),
) -> None:
    """Ask the five questions of the TelePreview questionnaire and store the answers with the session."""
    from rich.console import Console

    from teleprev.study import survey as sv

    console = Console()
    given = sv.parse_answers(answers) if answers is not None else sv.ask(console.input, lambda m: console.print(f"[red]{m}[/]"))
    path = sv.store(session, given, replace=replace)
    console.print(f"answers stored in {path}")


def study(
    sessions: list[Path] = typer.Argument(..., help="Session files (.mcap) of the study."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Folder for the CSV files and plots."),
    task: Optional[str] = typer.Option(None, "--task", help="Only this task's episodes (the paper's Table III uses pick_place)."),
    with_preview: Optional[str] = typer.Option(None, "--with-preview", help="The condition that is 'w/ preview' in Table III."),
    without_preview: Optional[str] = typer.Option(None, "--without-preview", help="The condition that is 'w/o preview'."),
) -> None:
    """Execution time, success, practice time and Likert ratings per condition and end effector; Table III."""
    from rich.console import Console

    from teleprev.study.report import plot_likert, plot_practice, print_tables, write_csv
    from teleprev.study.stats import group, session_facts, table_iii

    console = Console()
    facts = [session_facts(s) for s in sessions]
    groups = group(facts, task)
    rows = table_iii(groups, with_preview, without_preview)
    print_tables(console, groups, rows)
    missing = [f.path.name for f in facts if f.answers is None and not f.practice]
    if missing:
        console.print(f"[yellow]no survey for[/] {', '.join(missing)} (left out of the ratings, not counted as zero)")
    if out:
        practice: dict[str, list[float]] = {}
        for f in facts:
            if f.practice and f.practice_time_s is not None:
                practice.setdefault(f.condition, []).append(f.practice_time_s)
        written = write_csv(out, groups, rows) + [p for p in (plot_likert(out, groups), plot_practice(out, groups, practice)) if p]
        console.print(f"wrote {', '.join(str(p) for p in written)}")
