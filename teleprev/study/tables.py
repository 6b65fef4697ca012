"""The study's tables: on screen (rich), as CSV, and Table III in the paper's layout (markdown)."""

from __future__ import annotations

import csv
from pathlib import Path

from rich.console import Console
from rich.table import Table

from teleprev.robot.effectors import EFFECTORS
from teleprev.study.questionnaire import QUESTIONS
from teleprev.study.stats import Group, Summary, TableIIIRow

BETTER = "higher is better"
WORSE = "higher = more workload"


def _title(end_effector: str) -> str:
    return EFFECTORS[end_effector].title if end_effector in EFFECTORS else end_effector


def group_labels(groups: list[Group], sep: str = " · ") -> list[str]:
    """Each group named by its condition, plus its end effector where the groups' end effectors differ."""
    show_ee = len({g.end_effector for g in groups}) > 1
    return [(g.condition or "(no condition)") + (sep + (g.end_effector or "?") if show_ee else "") for g in groups]


def study_tasks(groups: list[Group]) -> list[str]:
    return list(dict.fromkeys(t for g in groups for t in g.tasks))


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.0%}"


def _with_n(s: Summary, digits: int = 1) -> str:
    return f"{s.text(digits)} (n={s.n})"


def improvement_text(r: TableIIIRow) -> str:
    return (
        "n/a"
        if r.improvement_s is None
        else f"{r.improvement_s:.1f}"
        if r.improvement_s < 0
        else f"+{r.improvement_s:.1f}"
    )


def print_tables(console: Console, groups: list[Group], rows: list[TableIIIRow], pooled: dict[str, list[str]]) -> None:
    t = Table(title="Per condition (execution time: successful, kept episodes, start to stop)", title_justify="left")
    t.add_column("measure", no_wrap=True)
    for label in group_labels(groups, "\n"):
        t.add_column(label, justify="right")
    t.add_row("sessions (participants)", *(f"{g.sessions} ({g.participants})" for g in groups))
    tasks = study_tasks(groups)
    for task in tasks:
        on = f", {task or '(no task)'}" if len(tasks) > 1 else ""
        stats = [g.tasks.get(task) for g in groups]
        t.add_row(
            f"execution time (s){on}", *("no episodes" if s is None else _with_n(s.execution_time_s) for s in stats)
        )
        t.add_row(
            f"success rate{on}",
            *(
                "no episodes"
                if s is None
                else f"{_pct(s.success_rate)} of {s.judged}" + (f", {s.unmarked} unmarked" if s.unmarked else "")
                for s in stats
            ),
        )
    if not tasks:
        t.add_row("execution time (s)", *("no episodes" for _ in groups))
    t.add_row(
        "practice time (s)", *(_with_n(g.practice_time_s) if g.practice_sessions else "no practice" for g in groups)
    )
    for q in QUESTIONS:
        t.add_row(f"{q.label} ({BETTER if q.higher_is_better else WORSE})",
                  *(_with_n(g.likert[q.key], 2) if g.surveys else "no survey" for g in groups))
    console.print(t)
    if not rows:
        console.print(
            "[yellow]Table III: no condition is w/ or w/o preview[/] (name them with --with-preview / "
            "--without-preview)"
        )
        return
    for task in dict.fromkeys(r.task for r in rows):
        t3 = Table(
            title=f"Table III{f' ({task})' if task else ''}: average execution time (s)",
            title_justify="left",
            caption="improvement = w/ - w/o; negative is faster with preview",
            caption_justify="left",
        )
        for col in ("End-Effector", "w/o Preview", "w/ Preview", "Improvement"):
            t3.add_column(col, justify="left" if col == "End-Effector" else "right")
        for r in rows:
            if r.task == task:
                t3.add_row(_title(r.end_effector), r.without.text(), r.with_.text(), improvement_text(r))
        console.print(t3)
    console.print(f"w/o preview: {', '.join(map(repr, pooled['without'])) or 'none'};  "
                  f"w/ preview: {', '.join(map(repr, pooled['with'])) or 'none'}", highlight=False)


def _cell(v):
    return "" if v is None else v  # missing stays empty in CSV, never 0


def write_csv(out: Path, groups: list[Group], rows: list[TableIIIRow]) -> list[Path]:
    """study.csv (per condition and end effector), execution_time.csv (per task too), table_iii.csv."""
    out.mkdir(parents=True, exist_ok=True)
    per_group = out / "study.csv"
    with per_group.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            [
                "condition",
                "end_effector",
                "sessions",
                "participants",
                "practice_sessions",
                "practice_time_mean_s",
                "practice_time_std_s",
                "practice_time_n",
                "surveys",
                "sessions_without_survey",
                *(f"{q.key}_{s}" for q in QUESTIONS for s in ("mean", "std", "n")),
            ]
        )
        for g in groups:
            p = g.practice_time_s
            w.writerow([g.condition, g.end_effector, g.sessions, g.participants,
                        g.practice_sessions, _cell(p.mean), _cell(p.std), p.n, g.surveys, g.not_surveyed,
                        *(_cell(getattr(g.likert[q.key], s)) for q in QUESTIONS for s in ("mean", "std", "n"))])
    per_task = out / "execution_time.csv"
    with per_task.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            [
                "condition",
                "end_effector",
                "task",
                "execution_time_mean_s",
                "execution_time_std_s",
                "execution_time_n",
                "success_rate",
                "episodes_judged",
                "episodes_unmarked",
            ]
        )
        for g in groups:
            for s in g.tasks.values():
                e = s.execution_time_s
                w.writerow(
                    [
                        g.condition,
                        g.end_effector,
                        s.task,
                        _cell(e.mean),
                        _cell(e.std),
                        e.n,
                        _cell(s.success_rate),
                        s.judged,
                        s.unmarked,
                    ]
                )
    table3 = out / "table_iii.csv"
    with table3.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            [
                "task",
                "end_effector",
                "without_mean_s",
                "without_std_s",
                "without_n",
                "with_mean_s",
                "with_std_s",
                "with_n",
                "improvement_s",
            ]
        )
        for r in rows:
            w.writerow([r.task, r.end_effector, _cell(r.without.mean), _cell(r.without.std), r.without.n,
                        _cell(r.with_.mean), _cell(r.with_.std), r.with_.n, _cell(r.improvement_s)])
    return [per_group, per_task, table3]


def write_table_iii_markdown(out: Path, rows: list[TableIIIRow]) -> Path:
    """Table III as in the paper: "23.6 ± 4.7" cells, one table per task."""
    lines = []
    for task in dict.fromkeys(r.task for r in rows):
        lines += [f"Average execution time (s){f', task {task}' if task else ''}", "",
                  "| End-Effector | w/o Preview | w/ Preview | Improvement |", "|---|---|---|---|"]
        lines += [f"| {_title(r.end_effector)} | {r.without.text()} | {r.with_.text()} | {improvement_text(r)} |"
                  for r in rows if r.task == task]
        lines.append("")
    path = out / "table_iii.md"
    path.write_text("\n".join(lines) + ("" if rows else "no condition is w/ or w/o preview\n"))
    return path
