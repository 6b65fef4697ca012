"""`teleprev survey` and `teleprev study`: the questionnaire after a condition, and the study's tables."""

from __future__ import annotations

from pathlib import Path

import typer


def survey(
    session: Path = typer.Argument(..., help="The session the participant just finished (.mcap)."),
    answers: str | None = typer.Option(
        None, "--answers", help="Scripted: the five answers 1-5 in order, e.g. 3,2,4,3,5."
    ),
    replace: bool = typer.Option(False, "--replace", help="Replace a survey already stored for this session."),
) -> None:
    """Ask the five questions of the TelePreview questionnaire (1-5) and store the answers next to the session."""
    from rich.console import Console
    from rich.markup import escape

    from teleprev.cli.outputs import check_output
    from teleprev.study import survey as sv

    console = Console(highlight=False)
    target = sv.target(session)
    sv.check_free(target, replace)  # before the participant answers anything
    check_output(target.sidecar, "the survey beside the session")
    if answers is not None:
        given = sv.parse_answers(answers)
    else:
        f = target.fields
        console.print(f"[b]Questionnaire[/] for {escape(session.name)}: participant {escape(f['participant'] or '?')}, "
                      f"condition {escape(f['condition'] or '?')}, {escape(f['end_effector'] or '?')}")
        if f["practice"] == "true":
            console.print(
                "[yellow]this is a practice session[/]; the questionnaire normally follows a condition's trials"
            )
        console.print("Rate 1 to 5. Higher means more, except the last question, where higher means more successful.")
        try:
            given = sv.ask(console.input, lambda m: console.print(f"[red]{escape(m)}[/]"))
        except (EOFError, KeyboardInterrupt):
            console.print("\n[yellow]survey not finished: nothing stored[/]")
            raise typer.Exit(1) from None
    path = sv.store(target, given, replace=replace)
    console.print(f"answers {', '.join(str(given[k]) for k in sv.KEYS)} stored in {escape(str(path))}")


def study(
    sessions: list[Path] = typer.Argument(..., help="Session files (.mcap) of the study, practice sessions included."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Folder for the CSV tables, table_iii.md and the plots."),
    task: str | None = typer.Option(
        None,
        "--task",
        help="Only this task's episodes in execution time, success rate and Table III "
        "(practice time and ratings are per condition).",
    ),
    with_preview: list[str] = typer.Option(
        [],
        "--with-preview",
        metavar="<str>",
        help="A condition that is 'w/ preview' in Table III (repeatable; "
        "replaces the automatic match of 'w/ preview', 'with preview', ...).",
    ),
    without_preview: list[str] = typer.Option(
        [], "--without-preview", metavar="<str>", help="A condition that is 'w/o preview' (repeatable)."
    ),
) -> None:
    """Execution time, success rate, practice time and Likert ratings per condition and end effector; Table III."""
    from rich.console import Console
    from rich.markup import escape

    from teleprev.cli.outputs import check_output
    from teleprev.errors import ConfigError
    from teleprev.study.facts import session_facts
    from teleprev.study.stats import ColumnMap, group, pooled_conditions, table_iii
    from teleprev.study.tables import group_labels, print_tables, write_csv, write_table_iii_markdown

    check_output(out, "--out", "folder", make_parents=True)
    console = Console(highlight=False)
    columns = ColumnMap(tuple(with_preview), tuple(without_preview))
    paths = list(dict.fromkeys(p.resolve() for p in sessions))  # a session named twice counts once
    facts = [session_facts(p) for p in paths]
    groups = group(facts, task)
    if task is not None and not any(g.tasks for g in groups):
        found = sorted({e.task or f.task for f in facts for e in f.episodes})
        raise ConfigError(
            f"no episode of task {task!r} in the {len(paths)} sessions (their tasks: {', '.join(found) or 'none'})",
            "--task",
        )
    rows = table_iii(facts, columns, task)
    print_tables(console, groups, rows, pooled_conditions(facts, columns))

    def note(what: str, names: list[str]) -> None:
        if names:
            console.print(f"[yellow]{what}:[/] {escape(', '.join(names))}")

    note(
        "no survey (left out of the ratings, not counted as zero)",
        [f.path.name for f in facts if f.answers is None and not f.practice],
    )
    note(
        "practice without a ready key (no practice time)",
        [f.path.name for f in facts if f.practice and f.practice_time_s is None],
    )
    note(
        "no successful episode (no execution time)",
        [
            f"{label}, {s.task or '(no task)'}"
            for g, label in zip(groups, group_labels(groups))
            for s in g.tasks.values()
            if s.execution_time_s.n == 0
        ],
    )
    unfinished = [
        f"{f.path.name} episode {e.index}"
        for f in facts
        if not f.practice
        for e in f.episodes
        if e.duration_s is None and not e.discarded and e.outcome == "success" and task in (None, e.task or f.task)
    ]
    note("successful episodes never stopped (left out of execution time)", unfinished)
    if out:
        from teleprev.study.plots import plot_likert, plot_practice

        written = write_csv(out, groups, rows) + [write_table_iii_markdown(out, rows)]
        for name, path in (
            ("likert.png", plot_likert(out, groups)),
            ("practice_time.png", plot_practice(out, groups, facts)),
        ):
            if path is None:
                console.print(
                    f"[yellow]{name} not written:[/] no {'surveys' if name == 'likert.png' else 'practice times'}"
                )
            else:
                written.append(path)
        console.print(f"wrote {escape(', '.join(str(p) for p in written))}")

